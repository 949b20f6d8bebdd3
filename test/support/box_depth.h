// Exact depth of a box room, for the tests of everything that reads depth images (OpenCV).
#pragma once

#include "view_selection/core/types.h"

#include "support/layers.h"

#include <opencv2/core.hpp>

namespace view_selection::test {

/// z-depth [m] of an axis-aligned box room [-hx, hx] x [-hy, hy] x [-hz, hz] seen from inside,
/// as a CV_32FC1 image of `k`'s size: exact ray casting against the six walls.
inline cv::Mat renderBoxDepth(const PinholeIntrinsics& k, const CameraPose& pose,
                              const Eigen::Vector3d& half) {
  cv::Mat depth(k.height, k.width, CV_32FC1);
  const Eigen::Matrix3d r = pose.rotation();
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray_cam = k.backProject(Eigen::Vector2d(u, v));  // z = 1
      const Eigen::Vector3d ray = r * ray_cam;
      double t_best = 1e300;
      for (int axis = 0; axis < 3; ++axis) {
        if (std::abs(ray[axis]) < 1e-12) continue;
        const double wall = ray[axis] > 0 ? half[axis] : -half[axis];
        const double t = (wall - pose.position[axis]) / ray[axis];
        if (t > 0 && t < t_best) t_best = t;
      }
      depth.at<float>(v, u) = static_cast<float>(t_best);  // z-depth, as ray_cam.z() == 1
    }
  }
  return depth;
}

}  // namespace view_selection::test
