// View selection on the error-resistance matrix (METHOD.md "Next view sets", "View check",
// "Completion", "Outputs"), written plainly: the reference. Deterministic: every tie breaks on
// the lower id. SelectionCache (selection_cache.h) keeps the same result current as the matrix
// changes; ChunkedSelection (chunked_selection.h) is the form it keeps and shares.
#pragma once

#include "view_selection/core/error_resistance_table.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <cstddef>
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

}  // namespace view_selection::core
