#include "view_selection/core/chunked_selection.h"

namespace view_selection::core {

std::pair<ViewId, ViewId> ChunkedSelection::initialPair() const {
  if (start_view < 0 || static_cast<size_t>(start_view) >= next_views.size() ||
      next_views[static_cast<size_t>(start_view)].empty())
    return {-1, -1};
  return {start_view, next_views[static_cast<size_t>(start_view)].front()};
}

ChunkedSelection ChunkedSelection::of(const Selection& plain) {
  ChunkedSelection s;
  s.next_views = {plain.next_views.begin(), plain.next_views.end()};
  s.final_next_views = {plain.final_next_views.begin(), plain.final_next_views.end()};
  s.start_view = plain.start_view;
  s.order = {plain.order.begin(), plain.order.end()};
  s.completed = {plain.completed.begin(), plain.completed.end()};
  s.isolated = {plain.isolated.begin(), plain.isolated.end()};
  s.pairs.resize(plain.final_next_views.size());
  for (const auto& [a, b] : plain.pairs) s.pairs.add(a, b);
  return s;
}

Selection ChunkedSelection::toSelection() const {
  Selection s;
  s.next_views = next_views.toVector();
  s.final_next_views = final_next_views.toVector();
  s.start_view = start_view;
  s.order = order.toVector();
  s.completed = completed.toVector();
  s.isolated = isolated.toVector();
  s.pairs = pairs.toVector();
  return s;
}

}  // namespace view_selection::core
