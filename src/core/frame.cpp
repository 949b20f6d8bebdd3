#include "view_selection/core/frame.h"

#include "view_selection/core/exceptions.h"

#include <cmath>
#include <sstream>
#include <string>

namespace view_selection::core {

void validateFrame(const Frame& frame) {
  if (!std::isfinite(frame.stamp)) throw InvalidInput("frame stamp is not finite");
  const PinholeIntrinsics& k = frame.intrinsics;
  if (!k.isValid()) {
    std::ostringstream s;
    s << "camera intrinsics are unusable (fx=" << k.fx << ", fy=" << k.fy << ", cx=" << k.cx
      << ", cy=" << k.cy << ", size " << k.width << "x" << k.height
      << "): focal lengths must be positive and finite, the size non-zero";
    throw InvalidInput(s.str());
  }
  if (!frame.pose.isValid())
    throw InvalidInput("camera pose is not finite or its quaternion is not of unit length");
  if (!frame.depth.empty()) {
    if (frame.depth.channels != 1)
      throw InvalidInput("depth must be one channel of metres (see images::depthToMetres)");
    // A depth image may be a scaled copy of the colour image, but with the same aspect ratio.
    const double ratio_image = static_cast<double>(k.width) / k.height;
    const double ratio_depth = static_cast<double>(frame.depth.width) / frame.depth.height;
    if (std::abs(ratio_image - ratio_depth) > 0.01 * ratio_image) {
      std::ostringstream s;
      s << "depth image is " << frame.depth.width << "x" << frame.depth.height
        << " but the camera is " << k.width << "x" << k.height << " (different aspect ratio)";
      throw InvalidInput(s.str());
    }
  }
  if (!frame.image.empty()) {
    if (frame.image.channels != 1 && frame.image.channels != 3 && frame.image.channels != 4)
      throw InvalidInput("image must be 8-bit grey, BGR or BGRA, got " +
                         std::to_string(frame.image.channels) + " channels");
    if (frame.image.width != k.width || frame.image.height != k.height) {
      std::ostringstream s;
      s << "image is " << frame.image.width << "x" << frame.image.height << " but camera_info says "
        << k.width << "x" << k.height;
      throw InvalidInput(s.str());
    }
  }
}

}  // namespace view_selection::core
