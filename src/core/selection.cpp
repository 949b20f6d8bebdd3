#include "view_selection/core/selection.h"

#include "selection_steps.h"

#include <algorithm>
#include <set>

namespace view_selection::core {

using detail::bestPredecessor;
using detail::completePaper;

void SelectionConfig::visitParameters(ParameterVisitor& v) {
  v.section("Selection");
  visitInteger(v, "k", k, 1, 1000, "next view set size");
  visitChoice(v, "completion", completion, kCompletionModeNames,
              "paper: each unreached view joins its best predecessor's set; reachable: from a "
              "visited view, and the traversal continues from it");
}

std::pair<ViewId, ViewId> Selection::initialPair() const {
  if (start_view < 0 || static_cast<size_t>(start_view) >= next_views.size() ||
      next_views[static_cast<size_t>(start_view)].empty())
    return {-1, -1};
  return {start_view, next_views[static_cast<size_t>(start_view)].front()};
}

std::vector<NextViewSet> computeNextViewSets(const ErrorResistanceTable& e, int k) {
  // One pass per row keeping the k best so far, sorted. A row is stored by ascending column,
  // so an entry that ties a kept value has the larger id and loses: plain `<` on the values
  // implements METHOD.md's (value, id) order. Most entries lose to the current k-th with one
  // comparison, so this is O(finite entries) with no copy of the row.
  const size_t keep = static_cast<size_t>(std::max(k, 0));
  std::vector<NextViewSet> sets(e.size());
  if (keep <= ErrorResistanceTable::kTopCapacity) {
    // The table keeps each row's best entries current: O(k) a row.
    for (size_t i = 0; i < e.size(); ++i) {
      const auto& top = e.top(static_cast<ViewId>(i));
      const size_t take = std::min(keep, top.size());
      sets[i].resize(take);
      for (size_t q = 0; q < take; ++q) sets[i][q] = top[q].view;
    }
    return sets;
  }
  std::vector<TableEntry> best(keep);
  for (size_t i = 0; i < e.size(); ++i) {
    size_t size = 0;
    if (keep > 0) {
      for (const TableEntry& entry : e.row(static_cast<ViewId>(i))) {
        if (size == keep && !(entry.value < best[keep - 1].value)) continue;
        size_t pos = size == keep ? keep - 1 : size++;
        while (pos > 0 && entry.value < best[pos - 1].value) {
          best[pos] = best[pos - 1];
          --pos;
        }
        best[pos] = entry;
      }
    }
    sets[i].resize(size);
    for (size_t q = 0; q < size; ++q) sets[i][q] = best[q].view;
  }
  return sets;
}

namespace {

/// Start view from the next view sets: C_i[0] is row i's smallest entry (ties to the smaller
/// column), so the smallest entry of E, ties to the smaller row, is the best of the C_i[0].
ViewId startViewFromSets(const ErrorResistanceTable& e, const std::vector<NextViewSet>& sets) {
  ViewId best_row = -1;
  double best_value = 0.0;
  for (size_t i = 0; i < sets.size(); ++i) {
    if (sets[i].empty()) continue;
    const double value = e.at(static_cast<ViewId>(i), sets[i].front());
    if (best_row < 0 || value < best_value) {  // rows ascend: a tie keeps the smaller row
      best_row = static_cast<ViewId>(i);
      best_value = value;
    }
  }
  return best_row;
}

}  // namespace

ViewId findStartView(const ErrorResistanceTable& e) {
  ViewId best_row = -1;
  ViewId best_col = -1;
  double best_value = 0.0;
  for (size_t i = 0; i < e.size(); ++i) {
    for (const TableEntry& entry : e.row(static_cast<ViewId>(i))) {
      const auto row = static_cast<ViewId>(i);
      if (best_row < 0 || entry.value < best_value ||
          (entry.value == best_value &&
           (row < best_row || (row == best_row && entry.view < best_col)))) {
        best_row = row;
        best_col = entry.view;
        best_value = entry.value;
      }
    }
  }
  return best_row;
}

namespace {

/// The depth-first traversal of `traverse`, over any storage of the sets (`set(i)` gives C_i).
template <typename Sets>
void traverseSets(const Sets& set, ViewId start, std::vector<char>& visited,
                  std::vector<ViewId>& order) {
  if (!visited[static_cast<size_t>(start)]) {
    visited[static_cast<size_t>(start)] = 1;
    order.push_back(start);
  }
  // Each stack frame keeps how far into its set it has looked: marks only accumulate, so a
  // candidate found marked once stays marked and is never looked at again.
  std::vector<std::pair<ViewId, size_t>> stack{{start, 0}};
  while (!stack.empty()) {
    auto& [current, cursor] = stack.back();
    const SetView candidates = set(current);
    while (cursor < candidates.size && visited[static_cast<size_t>(candidates.data[cursor])]) ++cursor;
    if (cursor == candidates.size) {
      stack.pop_back();  // all next views marked: return to the previous view
      continue;
    }
    const ViewId next = candidates.data[cursor];
    visited[static_cast<size_t>(next)] = 1;
    order.push_back(next);
    stack.emplace_back(next, 0);
  }
}

}  // namespace

void traverse(const std::vector<NextViewSet>& sets, ViewId start, std::vector<char>& visited,
              std::vector<ViewId>& order) {
  traverseSets(
      [&sets](ViewId i) {
        const NextViewSet& c = sets[static_cast<size_t>(i)];
        return SetView{c.data(), c.size()};
      },
      start, visited, order);
}

std::vector<std::pair<ViewId, ViewId>> pairsFromSets(const std::vector<NextViewSet>& sets) {
  std::vector<std::pair<ViewId, ViewId>> pairs;
  for (size_t i = 0; i < sets.size(); ++i)
    for (const ViewId j : sets[i])
      pairs.emplace_back(std::min(static_cast<ViewId>(i), j), std::max(static_cast<ViewId>(i), j));
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

namespace {

void completeReachable(const ErrorResistanceTable& e, std::vector<char>& visited, Selection& out) {
  // Unvisited views with a finite entry from some visited view, smallest id first.
  std::set<ViewId> candidates;
  size_t scanned = 0;  // views of `order` whose rows were already offered as candidates
  auto offerNewlyVisited = [&]() {
    for (; scanned < out.order.size(); ++scanned)
      for (const TableEntry& entry : e.row(out.order[scanned]))
        if (!visited[static_cast<size_t>(entry.view)]) candidates.insert(entry.view);
  };
  offerNewlyVisited();
  while (!candidates.empty()) {
    const ViewId x = *candidates.begin();
    candidates.erase(candidates.begin());
    if (visited[static_cast<size_t>(x)]) continue;
    const ViewId a = bestPredecessor(e, x, &visited);
    out.final_next_views[static_cast<size_t>(a)].push_back(x);
    out.completed.push_back({x, a});
    traverse(out.final_next_views, x, visited, out.order);  // marks x, then continues from it
    offerNewlyVisited();
  }
  for (size_t x = 0; x < e.size(); ++x)
    if (!visited[x]) out.isolated.push_back(static_cast<ViewId>(x));
}

}  // namespace

Selection selectViews(const ErrorResistanceTable& e, const SelectionConfig& config) {
  config.validate();
  Selection out;
  out.next_views = computeNextViewSets(e, config.k);
  out.final_next_views = out.next_views;
  out.start_view = config.k >= 1 ? startViewFromSets(e, out.next_views) : findStartView(e);
  std::vector<char> visited(e.size(), 0);
  if (out.start_view >= 0) traverse(out.next_views, out.start_view, visited, out.order);
  if (config.completion == CompletionMode::kPaper)
    completePaper(e, visited, out);
  else
    completeReachable(e, visited, out);
  out.pairs = pairsFromSets(out.final_next_views);
  return out;
}

}  // namespace view_selection::core
