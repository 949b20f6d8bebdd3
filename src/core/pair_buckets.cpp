#include "view_selection/core/pair_buckets.h"

#include <algorithm>
#include <iterator>
#include <stdexcept>

namespace view_selection::core {

bool PairBuckets::contains(ViewId a, ViewId b) const {
  const ViewId lo = std::min(a, b), hi = std::max(a, b);
  if (lo < 0 || static_cast<size_t>(lo) >= buckets_.size()) return false;
  const Bucket& bucket = buckets_[static_cast<size_t>(lo)];
  const auto it = std::lower_bound(bucket.begin(), bucket.end(), hi,
                                   [](const Entry& e, ViewId v) { return e.hi < v; });
  return it != bucket.end() && it->hi == hi;
}

std::vector<std::pair<ViewId, ViewId>> PairBuckets::toVector() const {
  std::vector<std::pair<ViewId, ViewId>> out;
  out.reserve(count_);
  for (const auto& pair : *this) out.push_back(pair);
  return out;
}

bool PairBuckets::add(ViewId a, ViewId b) {
  const ViewId lo = std::min(a, b), hi = std::max(a, b);
  Bucket& bucket = buckets_.edit(static_cast<size_t>(lo));
  const auto it = std::lower_bound(bucket.begin(), bucket.end(), hi,
                                   [](const Entry& e, ViewId v) { return e.hi < v; });
  if (it != bucket.end() && it->hi == hi) {
    ++it->sets;
    return false;
  }
  bucket.insert(it, {hi, 1});
  ++count_;
  return true;
}

bool PairBuckets::remove(ViewId a, ViewId b) {
  const ViewId lo = std::min(a, b), hi = std::max(a, b);
  Bucket& bucket = buckets_.edit(static_cast<size_t>(lo));
  const auto it = std::lower_bound(bucket.begin(), bucket.end(), hi,
                                   [](const Entry& e, ViewId v) { return e.hi < v; });
  if (it == bucket.end() || it->hi != hi) throw std::logic_error("PairBuckets::remove: no such pair");
  if (--it->sets > 0) return false;
  bucket.erase(it);
  --count_;
  return true;
}

PairChanges pairChanges(const std::vector<std::pair<ViewId, ViewId>>& before,
                        const std::vector<std::pair<ViewId, ViewId>>& after) {
  PairChanges c;
  std::set_difference(after.begin(), after.end(), before.begin(), before.end(),
                      std::back_inserter(c.added));
  std::set_difference(before.begin(), before.end(), after.begin(), after.end(),
                      std::back_inserter(c.removed));
  return c;
}

}  // namespace view_selection::core
