// RViz markers for a selection: one frustum per keyframe, next-view edges, completion edges in
// another colour, the start view highlighted.
#pragma once

#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/selection.h"

#include <visualization_msgs/MarkerArray.h>

#include <string>

namespace view_selection {
namespace ros_node {

/// Namespaces: "frusta", "start_view", "next_views", "completion". Each is one marker that is
/// replaced on every call (a DELETEALL first clears markers of a larger earlier selection).
/// `scale` is the frustum depth [m, scene units].
visualization_msgs::MarkerArray selectionMarkers(const ErrorResistanceMatrix& matrix,
                                                 const Selection& selection,
                                                 const std::string& world_frame, double scale);

}  // namespace ros_node
}  // namespace view_selection
