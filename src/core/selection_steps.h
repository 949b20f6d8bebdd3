// Steps of selectViews that SelectionCache takes the same way (private to src/core): the
// method's order of entries, the best predecessor of a view, and paper completion into either
// form of a selection.
#pragma once

#include "view_selection/core/chunked_selection.h"
#include "view_selection/core/chunked_vector.h"
#include "view_selection/core/error_resistance_table.h"
#include "view_selection/core/selection.h"

#include <algorithm>
#include <vector>

namespace view_selection::core::detail {

/// Strict order of METHOD.md: by value, then by id.
inline bool better(double value_a, ViewId id_a, double value_b, ViewId id_b) {
  return value_a < value_b || (value_a == value_b && id_a < id_b);
}

inline NextViewSet& setToChange(std::vector<NextViewSet>& sets, size_t i) { return sets[i]; }
inline NextViewSet& setToChange(ChunkedVector<NextViewSet>& sets, size_t i) { return sets.edit(i); }

/// Best a (by (E[a][x], a)) over column x, optionally among visited views only; -1 if none.
inline ViewId bestPredecessor(const ErrorResistanceTable& e, ViewId x,
                              const std::vector<char>* visited) {
  ViewId best = -1;
  double best_value = 0.0;
  for (const TableEntry& entry : e.column(x)) {
    if (visited && !(*visited)[static_cast<size_t>(entry.view)]) continue;
    if (best < 0 || better(entry.value, entry.view, best_value, best)) {
      best = entry.view;
      best_value = entry.value;
    }
  }
  return best;
}

/// Paper completion into a Selection or a ChunkedSelection.
template <typename Out>
void completePaper(const ErrorResistanceTable& e, const std::vector<char>& visited, Out& out) {
  for (size_t x = 0; x < e.size(); ++x) {
    if (visited[x]) continue;
    const ViewId a = bestPredecessor(e, static_cast<ViewId>(x), nullptr);
    if (a < 0) {
      out.isolated.push_back(static_cast<ViewId>(x));
      continue;
    }
    // x may already be in C_a (a itself unvisited): the set stays free of duplicates, and the
    // completion is still reported.
    const auto& set = out.final_next_views[static_cast<size_t>(a)];
    if (std::find(set.begin(), set.end(), static_cast<ViewId>(x)) == set.end())
      setToChange(out.final_next_views, static_cast<size_t>(a)).push_back(static_cast<ViewId>(x));
    out.completed.push_back({static_cast<ViewId>(x), a});
  }
}

}  // namespace view_selection::core::detail
