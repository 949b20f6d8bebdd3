// The pairs of a selection as the node keeps and shares them (PairBuckets), and the pairs that
// appeared and went between two selections (PairChanges).
#pragma once

#include "view_selection/core/chunked_vector.h"
#include "view_selection/core/types.h"

#include <cstddef>
#include <cstdint>
#include <iterator>
#include <utility>
#include <vector>

namespace view_selection::core {

/// The pairs of a selection, bucketed by their smaller id: bucket lo holds the larger ids hi of
/// the pairs {lo, hi}, ascending, each with the number of final sets it comes from (C_lo holding
/// hi, C_hi holding lo: 1 or 2). Chunked and shared between copies, so that a copy costs a
/// pointer a chunk and a change copies only the buckets' chunks it touches.
class PairBuckets {
 public:
  struct Entry {
    ViewId hi;
    std::uint32_t sets;  ///< final sets the pair comes from
    bool operator==(const Entry& o) const { return hi == o.hi && sets == o.sets; }
  };
  using Bucket = std::vector<Entry>;

  /// Pairs in all.
  size_t size() const { return count_; }
  bool empty() const { return count_ == 0; }
  /// Buckets: one per view.
  size_t buckets() const { return buckets_.size(); }
  const Bucket& bucket(ViewId lo) const { return buckets_[static_cast<size_t>(lo)]; }
  bool contains(ViewId a, ViewId b) const;
  std::vector<std::pair<ViewId, ViewId>> toVector() const;

  /// The pairs in order (lo ascending, then hi).
  class const_iterator {
   public:
    using iterator_category = std::forward_iterator_tag;
    using value_type = std::pair<ViewId, ViewId>;
    using difference_type = std::ptrdiff_t;
    using pointer = void;
    using reference = value_type;
    const_iterator(const PairBuckets* p, size_t lo, size_t q) : p_(p), lo_(lo), q_(q) { skip(); }
    value_type operator*() const {
      return {static_cast<ViewId>(lo_), p_->buckets_[lo_][q_].hi};
    }
    const_iterator& operator++() {
      ++q_;
      skip();
      return *this;
    }
    bool operator==(const const_iterator& o) const { return lo_ == o.lo_ && q_ == o.q_; }
    bool operator!=(const const_iterator& o) const { return !(*this == o); }

   private:
    void skip() {
      while (lo_ < p_->buckets_.size() && q_ >= p_->buckets_[lo_].size()) {
        ++lo_;
        q_ = 0;
      }
    }
    const PairBuckets* p_;
    size_t lo_, q_;
  };
  const_iterator begin() const { return {this, 0, 0}; }
  const_iterator end() const { return {this, buckets_.size(), 0}; }

  // Changes (SelectionCache): one more or one fewer final set holding the pair {a, b}. Return
  // true when the pair itself appeared or went.
  bool add(ViewId a, ViewId b);
  bool remove(ViewId a, ViewId b);
  void resize(size_t views) { buckets_.resize(views); }
  void clear() {
    buckets_.clear();
    count_ = 0;
  }

 private:
  ChunkedVector<Bucket> buckets_;
  size_t count_ = 0;
};

/// Pairs that appeared and went, each as i < j, sorted.
struct PairChanges {
  std::vector<std::pair<ViewId, ViewId>> added;
  std::vector<std::pair<ViewId, ViewId>> removed;
  bool empty() const { return added.empty() && removed.empty(); }
};

/// The added and removed pairs between two selections (a plain set difference; for tests and
/// for selections that do not come from one SelectionCache).
PairChanges pairChanges(const std::vector<std::pair<ViewId, ViewId>>& before,
                        const std::vector<std::pair<ViewId, ViewId>>& after);

}  // namespace view_selection::core
