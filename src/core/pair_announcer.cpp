#include "view_selection/core/pair_announcer.h"

#include <algorithm>

namespace view_selection::core {

Announcement PairAnnouncer::update(const PairChanges& changes, std::size_t keyframes) {
  Announcement out;
  for (const Pair& p : changes.removed) {
    if (pending_.erase(p)) continue;  // never announced: nothing to take back
    if (announced_.erase(p)) out.removed.push_back(p);
  }
  for (const Pair& p : changes.added)
    if (!announced_.count(p)) pending_[p] = keyframes;
  Announcement due = releaseDue(keyframes, false);
  out.added = std::move(due.added);
  std::sort(out.removed.begin(), out.removed.end());
  return out;
}

Announcement PairAnnouncer::flush() { return releaseDue(0, true); }

Announcement PairAnnouncer::releaseDue(std::size_t keyframes, bool all) {
  Announcement out;
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (all || keyframes >= it->second + static_cast<std::size_t>(std::max(0, stable_keyframes_))) {
      announced_.insert(it->first);
      out.added.push_back(it->first);  // the map is ordered: sorted
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
  return out;
}

void PairAnnouncer::clear() {
  announced_.clear();
  pending_.clear();
}

void PairAnnouncer::announceAll(const std::vector<Pair>& pairs) {
  pending_.clear();
  announced_ = std::set<Pair>(pairs.begin(), pairs.end());
}

}  // namespace view_selection::core
