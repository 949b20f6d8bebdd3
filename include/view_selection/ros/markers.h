// RViz markers for a selection: one frustum per keyframe, next-view edges, completion edges in
// another colour, the start view highlighted.
#pragma once

#include "view_selection/core/selection_output.h"

#include <visualization_msgs/MarkerArray.h>

#include <string>

namespace view_selection::ros_node {

/// Namespaces: "frusta", "start_view", "next_views", "completion", "revisits" (a keyframe with a
/// revisit_of to the keyframe it revisits). Each is one marker that is
/// replaced on every call (a DELETEALL first clears markers of a larger earlier selection).
/// `scale` is the frustum depth [m, scene units]. Above `max_views` keyframes (0: never) only a
/// summary is drawn: the frusta and final next-view edges of every m-th view, m = ceil(n /
/// max_views), and of the start view and the newest keyframe, so at most max_views + 2 views.
visualization_msgs::MarkerArray selectionMarkers(const core::SelectionOutput& snapshot,
                                                 const std::string& world_frame, double scale,
                                                 size_t max_views = 0);

}  // namespace view_selection::ros_node
