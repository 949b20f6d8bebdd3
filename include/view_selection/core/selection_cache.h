// selectViews (selection.h) kept current as the error-resistance table changes, in time that
// does not grow with the number of finite entries.
#pragma once

#include "view_selection/core/chunked_selection.h"
#include "view_selection/core/chunked_vector.h"
#include "view_selection/core/error_resistance_table.h"
#include "view_selection/core/pair_buckets.h"
#include "view_selection/core/selection.h"
#include "view_selection/core/types.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <queue>
#include <vector>

namespace view_selection::core {

/// selectViews kept current as a table changes (keyframes added, rows recomputed): equal to
/// selectViews(e, config) after every update (a property test holds it to that).
///   - next view sets are recomputed only for rows whose ErrorResistanceTable::rowVersion moved;
///   - the start view is the best of the cached C_i[0] values: O(n) comparisons of doubles;
///   - with reachable completion, the traversal and completion are resumed, not redone: up to
///     the first position of the order whose view's row changed they read only unchanged rows
///     (the sets, the candidates and the predecessors are all functions of the visited views'
///     rows), so they are kept; from that position on they run again, from the depth-first
///     stack rebuilt from the recorded parents, and completion looks again only at the views
///     from that position on (and the unreached and new ones). A keyframe of a SLAM walk
///     changes rows near the end of the order, so an update redoes a handful of views;
///   - otherwise (s or its set changed, paper completion) the traversal runs in full, O(n k),
///     and completion looks at the columns of the views the traversal did not reach and at the
///     rows of the views completion then reaches;
///   - pairs are bucketed by their smaller id and counted again only for the final sets that
///     changed (PairBuckets), which also gives the pairs that appeared and went;
///   - the result is a ChunkedSelection: a copy of it for readers shares every chunk.
/// What remains O(n) per update is the version check of every row, the start view and the scan
/// for isolated views: a few comparisons a view.
class SelectionCache {
 public:
  /// The selection for `e` now. The reference stays valid until the next update or clear; a
  /// copy of it is cheap and stays valid.
  const ChunkedSelection& update(const ErrorResistanceTable& e, const SelectionConfig& config);
  const ChunkedSelection& selection() const { return selection_; }
  void clear();
  /// With tracking on, the pairs that appeared and went are kept from one takePairChanges() to
  /// the next (netted: a pair that went and came back is neither); off, nothing is kept.
  void trackPairChanges(bool on);
  PairChanges takePairChanges();
  /// Updates that resumed reachable completion instead of redoing the traversal (for tests and
  /// benchmarks), and all updates.
  size_t resumedUpdates() const { return resumed_updates_; }
  /// ... of which resumed inside a traversal (from its rebuilt stack).
  size_t resumedInsideTraversal() const { return resumed_inside_; }
  size_t updates() const { return updates_; }

 private:
  /// Rows whose version moved (or that are new) into changed_, and their first values.
  void findChangedRows(const ErrorResistanceTable& e);
  /// Recomputes the sets of changed_ rows (their final sets become the plain ones).
  void refreshSets(const ErrorResistanceTable& e);
  /// Back to the plain sets everywhere (completion's appends undone).
  void resetFinalSets();
  /// The position from which the previous traversal and completion no longer hold, or -1 when
  /// they must be redone from the start.
  std::ptrdiff_t resumePosition(ViewId start) const;
  /// Depth-first traversal from the frames on stack_ over `sets`, recording order positions and
  /// parents.
  template <typename Sets>
  void traverseFrom(const Sets& sets);
  void visit(ViewId v, ViewId parent);
  void completePaper(const ErrorResistanceTable& e);
  void completeReachable(const ErrorResistanceTable& e);
  /// Reachable completion resumed at order position p (the previous run up to p stands).
  void resumeReachable(const ErrorResistanceTable& e, size_t p);
  /// Undoes the completions whose traversal started at or after p (last first).
  void undoCompletionsFrom(size_t p);
  /// Completion's loop: candidates in the heap, each traversal then offering its views' rows.
  void completionLoop(const ErrorResistanceTable& e);
  void offer(ViewId x);
  /// Offers x when it is unvisited and has a finite entry from a visited view.
  void offerIfReached(const ErrorResistanceTable& e, ViewId x);
  /// Marks final set a as changed since the pairs were last counted.
  void finalSetChanged(ViewId a);
  /// Counts the changed final sets' pairs again (O(changed sets x their sizes)).
  void updatePairs();
  void logPair(ViewId a, ViewId b, bool added);
  SetView plainSet(ViewId i) const;  ///< C_i
  SetView finalSet(ViewId i) const;  ///< C_i after completion so far

  SelectionConfig config_;
  bool configured_ = false;
  ChunkedSelection selection_;
  std::vector<std::uint64_t> seen_;    ///< rowVersion each cached C_i was computed at
  std::vector<double> first_value_;    ///< E[i][C_i[0]], +inf when C_i is empty
  std::vector<ViewId> extended_rows_;  ///< rows whose final set completion lengthened last time
  std::vector<char> extended_;         ///< the same as a flag per row
  size_t flat_stride_ = 0;             ///< k when the sets are also kept flat (k <= 16), else 0
  std::vector<ViewId> flat_;           ///< C_i at [i * k, i * k + |C_i|)
  std::vector<std::uint32_t> flat_size_;
  std::vector<char> visited_;
  std::vector<char> queued_;  ///< offered to reachable completion
  std::vector<ViewId> changed_;          ///< rows changed since the last update, ascending
  size_t previous_size_ = 0;             ///< e.size() at the last update
  ViewId previous_start_ = -1;
  bool resumable_ = false;               ///< the record below describes the last selection
  std::vector<std::int32_t> position_;   ///< of each view in order, -1: not visited
  std::vector<ViewId> parent_;           ///< whose set the traversal reached it from, -1: a root
  size_t plain_length_ = 0;              ///< views the traversal from s reached
  std::vector<std::pair<ViewId, size_t>> stack_;  ///< (view, cursor into its set)
  std::priority_queue<ViewId, std::vector<ViewId>, std::greater<ViewId>> candidates_;
  std::vector<ViewId> reexamine_;  ///< views a resumed completion looks at again
  size_t resumed_updates_ = 0, resumed_inside_ = 0, updates_ = 0;
  ChunkedVector<NextViewSet> counted_;  ///< the final sets as selection_.pairs counts them
  std::vector<ViewId> final_changed_;   ///< final sets changed since, each once
  std::vector<char> final_changed_flag_;
  bool track_pair_changes_ = false;
  struct PairEvent {
    ViewId lo, hi;
    bool added;
  };
  std::vector<PairEvent> pair_log_;  ///< with tracking: since the last takePairChanges()
};

}  // namespace view_selection::core
