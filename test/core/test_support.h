// Helpers shared by the core tests: seeded random cameras and look-at poses.
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Geometry>

#include <random>

namespace view_selection::test {

inline PinholeIntrinsics vgaIntrinsics(double f = 525.0) {
  PinholeIntrinsics k;
  k.fx = f;
  k.fy = f;
  k.cx = 319.5;
  k.cy = 239.5;
  k.width = 640;
  k.height = 480;
  return k;
}

/// Camera at `eye` whose optical axis (z) points at `target`, with `roll` about that axis [rad].
inline CameraPose lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                         double roll = 0.0) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d helper = std::abs(z.y()) < 0.9 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitX();
  Eigen::Vector3d x = helper.cross(z).normalized();  // image x to the right when y is "down"
  Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(1) = y;
  r.col(2) = z;
  r = r * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  CameraPose pose;
  pose.position = eye;
  pose.orientation = Eigen::Quaterniond(r);
  return pose;
}

inline Eigen::Vector3d randomUnit(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
}

}  // namespace view_selection::test

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
