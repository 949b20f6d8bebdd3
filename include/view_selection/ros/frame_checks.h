// The worker's first look at a frame, before any lock: its messages checked (image and depth
// encodings, depth registered to the colour camera, sizes against camera_info) and its camera
// model made. A frame that fails is dropped with the reason this gives.
#pragma once

#include "view_selection/ros/camera_model.h"
#include "view_selection/ros/frame_queue.h"

#include <optional>
#include <string>

namespace view_selection::ros_node {

/// Why a frame cannot be used: a drop reason (~statistics) and a message.
struct FrameDefect {
  std::string reason;
  std::string message;
};

/// Checks `frame` and fills `camera` from its camera_info; the defect when it is unusable.
std::optional<FrameDefect> checkFrame(const PendingFrame& frame, CameraModel& camera);

}  // namespace view_selection::ros_node
