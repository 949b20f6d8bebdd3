#include "view_selection/ros/frame_checks.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/ros/conversions.h"
#include "view_selection/ros/node_config.h"

#include <sstream>

namespace view_selection::ros_node {

std::optional<FrameDefect> checkFrame(const PendingFrame& frame, CameraModel& camera) {
  const sensor_msgs::Image& image = *frame.image;
  try {
    checkImageMessage(image, "image");
  } catch (const core::InvalidInput& e) {
    return FrameDefect{"bad_image", e.what()};
  }
  if (frame.depth) {
    try {
      checkImageMessage(*frame.depth, "depth");
      checkDepthEncoding(*frame.depth);
    } catch (const core::InvalidInput& e) {
      return FrameDefect{"bad_depth", e.what()};
    }
    // Depth sampled at colour pixels must be registered to the colour camera.
    const std::string depth_frame = normaliseFrameId(frame.depth->header.frame_id);
    const std::string image_frame = normaliseFrameId(image.header.frame_id);
    if (!depth_frame.empty() && !image_frame.empty() && depth_frame != image_frame)
      return FrameDefect{"bad_depth",
                         "the depth image is in frame '" + depth_frame +
                             "', not the colour image's '" + image_frame +
                             "': use depth registered to the colour camera (e.g. "
                             "depth_registered, aligned_depth_to_color)"};
  }
  try {
    camera = cameraModelFromInfo(*frame.info);
  } catch (const core::InvalidInput& e) {
    return FrameDefect{"bad_camera_info", e.what()};
  }
  const core::PinholeIntrinsics& k = camera.intrinsics;
  if (image.width != static_cast<uint32_t>(k.width) ||
      image.height != static_cast<uint32_t>(k.height)) {
    std::ostringstream s;
    s << "image is " << image.width << "x" << image.height << " but camera_info says " << k.width
      << "x" << k.height
      << (frame.info->binning_x > 1 || frame.info->binning_y > 1 || frame.info->roi.width > 0
              ? " (with its binning and ROI)"
              : "");
    return FrameDefect{"bad_camera_info", s.str()};
  }
  return std::nullopt;
}

}  // namespace view_selection::ros_node
