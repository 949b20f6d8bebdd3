// The pair stream's stability rule: which of the selection's pairs are announced to a consumer
// that matches them while the camera still moves (a COLMAP bridge). A pair the selection takes
// is announced once it is still selected `stable_keyframes` keyframes later; a pair that leaves
// the selection before that was never announced and costs the consumer nothing. A pair that
// leaves after it was announced is announced as removed (the consumer may already have matched
// it: that matching is wasted). flush() announces every pending pair at once (the recording
// paused or ended: nothing will confirm them any more).
//
// Measured on the kitchen (docs/live.md): announcing at once (stable_keyframes 0) wastes about a
// fifth of the matching; a few keyframes of patience take it under a tenth.
#pragma once

#include "view_selection/core/pair_buckets.h"
#include "view_selection/core/types.h"

#include <cstddef>
#include <map>
#include <set>
#include <utility>
#include <vector>

namespace view_selection::core {

using Pair = std::pair<ViewId, ViewId>;

/// What changes for the consumer: pairs to match now, and announced pairs no longer selected.
struct Announcement {
  std::vector<Pair> added;    ///< sorted
  std::vector<Pair> removed;  ///< sorted
  bool empty() const { return added.empty() && removed.empty(); }
};

class PairAnnouncer {
 public:
  explicit PairAnnouncer(int stable_keyframes = 0) : stable_keyframes_(stable_keyframes) {}

  /// The selection's pairs changed by `changes` (SelectionCache::takePairChanges) and it now has
  /// `keyframes` keyframes. Returns what is announced.
  Announcement update(const PairChanges& changes, std::size_t keyframes);
  /// Announces every pending pair.
  Announcement flush();
  /// Forgets everything (a new session).
  void clear();
  /// Every pair of the selection counts as announced at once (a session continued from a saved
  /// state: its consumer matched them, or will when it catches up on the whole set).
  void announceAll(const std::vector<Pair>& pairs);

  const std::set<Pair>& announced() const { return announced_; }
  std::size_t pending() const { return pending_.size(); }
  int stableKeyframes() const { return stable_keyframes_; }
  void setStableKeyframes(int m) { stable_keyframes_ = m; }

 private:
  Announcement releaseDue(std::size_t keyframes, bool all);

  int stable_keyframes_;
  std::set<Pair> announced_;
  std::map<Pair, std::size_t> pending_;  ///< pair -> keyframes when it was (last) selected
};


}  // namespace view_selection::core
