// View selection on the error-resistance matrix (METHOD.md "Next view sets", "View check",
// "Completion", "Outputs"). Deterministic: every tie breaks on the lower id.
#pragma once

#include "view_selection/core/error_resistance_table.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <cstdint>
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
///   - the traversal runs in full, O(n k), with storage kept between updates;
///   - completion looks at the columns of the views the traversal did not reach, and at the
///     rows of the views completion then reaches, never at every finite entry;
///   - pairs are bucketed by their smaller id, O(n k) plus a sort of each bucket.
/// What remains O(n) per update is the traversal, the start view and the pairs.
class SelectionCache {
 public:
  /// The selection for `e` now. The reference stays valid until the next update or clear.
  const Selection& update(const ErrorResistanceTable& e, const SelectionConfig& config);
  const Selection& selection() const { return selection_; }
  void clear();

 private:
  void refreshSets(const ErrorResistanceTable& e);
  void completePaper(const ErrorResistanceTable& e);
  void completeReachable(const ErrorResistanceTable& e);
  void buildPairs();
  SetView plainSet(ViewId i) const;  ///< C_i
  SetView finalSet(ViewId i) const;  ///< C_i after completion so far

  SelectionConfig config_;
  bool configured_ = false;
  Selection selection_;
  std::vector<std::uint64_t> seen_;    ///< rowVersion each cached C_i was computed at
  std::vector<double> first_value_;    ///< E[i][C_i[0]], +inf when C_i is empty
  std::vector<ViewId> extended_rows_;  ///< rows whose final set completion lengthened last time
  std::vector<char> extended_;         ///< the same as a flag per row
  size_t flat_stride_ = 0;             ///< k when the sets are also kept flat (k <= 16), else 0
  std::vector<ViewId> flat_;           ///< C_i at [i * k, i * k + |C_i|)
  std::vector<std::uint32_t> flat_size_;
  std::vector<char> visited_;
  std::vector<char> queued_;  ///< offered to reachable completion
  std::vector<std::size_t> bucket_begin_;  ///< pairs by smaller id (CSR)
  std::vector<ViewId> bucket_;
};

}  // namespace view_selection::core
