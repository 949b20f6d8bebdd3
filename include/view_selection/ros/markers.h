// RViz markers for a selection: one frustum per keyframe, next-view edges, completion edges in
// another colour, the start view highlighted.
#pragma once

#include "view_selection/core/selection_snapshot.h"

#include <visualization_msgs/MarkerArray.h>

#include <string>

namespace view_selection::ros_node {

/// Namespaces: "frusta", "start_view", "next_views", "completion". Each is one marker that is
/// replaced on every call (a DELETEALL first clears markers of a larger earlier selection).
/// `scale` is the frustum depth [m, scene units].
visualization_msgs::MarkerArray selectionMarkers(const core::SelectionSnapshot& snapshot,
                                                 const std::string& world_frame, double scale);

}  // namespace view_selection::ros_node
