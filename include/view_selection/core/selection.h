// View selection on the error-resistance matrix (METHOD.md "Next view sets", "View check",
// "Completion", "Outputs"). Deterministic: every tie breaks on the lower id.
#pragma once

#include "view_selection/core/chunked_vector.h"
#include "view_selection/core/error_resistance_table.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <queue>
#include <string>
#include <utility>
#include <vector>

namespace view_selection::core {

enum class CompletionMode {
  kPaper,      ///< each unvisited view joins the set of its best predecessor; order unchanged
  kReachable,  ///< each added view joins from a visited view and the traversal continues from it
};

inline constexpr EnumNames<CompletionMode, 2> kCompletionModeNames{
    {{CompletionMode::kPaper, "paper"}, {CompletionMode::kReachable, "reachable"}}};

inline std::string toString(CompletionMode mode) { return nameOf(mode, kCompletionModeNames); }
/// "paper" or "reachable"; throws InvalidArgument otherwise.
inline CompletionMode completionModeFromString(const std::string& text) {
  return valueOf(text, kCompletionModeNames, "completion");
}

struct SelectionConfig {
  int k = 5;  ///< size of each next view set
  CompletionMode completion = CompletionMode::kReachable;

  void visitParameters(ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const { checkRanges(*this); }
};

/// The next view set C_i: up to k views, best (lowest E[i][j], then lowest j) first.
using NextViewSet = std::vector<ViewId>;

struct CompletedView {
  ViewId view;      ///< x, a view the traversal did not reach
  ViewId added_to;  ///< a, whose set x was appended to
  bool operator==(const CompletedView& o) const { return view == o.view && added_to == o.added_to; }
};

struct Selection {
  std::vector<NextViewSet> next_views;           ///< C_i before completion
  std::vector<NextViewSet> final_next_views;     ///< C_i after completion
  ViewId start_view = -1;                        ///< s; -1 when E has no finite entry
  std::vector<ViewId> order;                     ///< traversal order (extended in reachable mode)
  std::vector<CompletedView> completed;          ///< in the order they were added
  std::vector<ViewId> isolated;                  ///< ascending
  std::vector<std::pair<ViewId, ViewId>> pairs;  ///< undirected, i < j, sorted

  /// (s, C_s[0]); {-1, -1} when there is no start view or C_s is empty.
  std::pair<ViewId, ViewId> initialPair() const;
};

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

/// A Selection as SelectionCache keeps it and the node's outputs read it: the same fields, with
/// every per-view list chunked and shared between copies (ChunkedVector, PairBuckets), so that
/// a copy for readers costs O(n / 256) and not O(n).
struct ChunkedSelection {
  ChunkedVector<NextViewSet> next_views;        ///< C_i before completion
  ChunkedVector<NextViewSet> final_next_views;  ///< C_i after completion
  ViewId start_view = -1;
  ChunkedVector<ViewId> order;
  ChunkedVector<CompletedView> completed;
  ChunkedVector<ViewId> isolated;
  PairBuckets pairs;

  std::pair<ViewId, ViewId> initialPair() const;
  /// The plain Selection with the same content, O(n).
  Selection toSelection() const;
  /// The chunked form of a plain Selection (each pair counted once), O(n).
  static ChunkedSelection of(const Selection& plain);
};

/// C_i for every row: the first k finite entries of row i sorted by (E[i][j], j).
std::vector<NextViewSet> computeNextViewSets(const ErrorResistanceTable& e, int k);

/// s: the row of the smallest finite entry of E, ties by (E, i, j); -1 when none.
ViewId findStartView(const ErrorResistanceTable& e);

/// Depth-first traversal from `start` over `sets`, continuing a visit in progress: views already
/// marked in `visited` are skipped, newly reached ones are marked and appended to `order`.
void traverse(const std::vector<NextViewSet>& sets, ViewId start, std::vector<char>& visited,
              std::vector<ViewId>& order);

/// The undirected, de-duplicated pairs {i, j}, j in sets[i], each as i < j, sorted.
std::vector<std::pair<ViewId, ViewId>> pairsFromSets(const std::vector<NextViewSet>& sets);

/// Everything of METHOD.md's "Outputs" for one matrix. The definition, written plainly;
/// SelectionCache gives the same result after small changes in time that does not grow with
/// the number of finite entries.
Selection selectViews(const ErrorResistanceTable& e, const SelectionConfig& config);

/// A view's set as the traversal reads it, wherever it is stored: a pointer and a length.
struct SetView {
  const ViewId* data;
  size_t size;
};

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
