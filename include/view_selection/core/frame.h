// One incoming frame, already converted from files or messages: what the keyframe policy, the
// point source and the matrix need to make a keyframe of it.
#pragma once

#include "view_selection/core/image.h"
#include "view_selection/core/types.h"

#include <string>

namespace view_selection::core {

struct Frame {
  double stamp = 0.0;      ///< [s]
  std::string image_name;  ///< name used in pairs.txt
  PinholeIntrinsics intrinsics;
  CameraPose pose;                 ///< camera-to-world, optical frame
  DepthImage depth;                ///< metres (0 = invalid), or empty when there is no depth
  ColourImage image;               ///< colour (BGR) or grey; may be empty for depth-only sources
  bool external_keyframe = false;  ///< keyframe_policy external: the outside verdict
};

/// Throws InvalidInput when a frame cannot be used (stamp, intrinsics, pose, image and depth
/// sizes).
void validateFrame(const Frame& frame);

}  // namespace view_selection::core
