// Helpers shared by the tests: seeded random cameras and look-at poses.
#pragma once

#include "view_selection/core/types.h"

#include "support/layers.h"

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
  Eigen::Vector3d helper =
      std::abs(z.y()) < 0.9 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitX();
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

/// Three draws of `d`, z first: the order gcc evaluated `Vector3d(d(rng), d(rng), d(rng))` in.
/// Argument order is unspecified (clang goes x first), so seeded scenes drawn that way were
/// compiler-dependent; drawn through this they are what the tests' thresholds were set on.
template <typename Distribution>
Eigen::Vector3d drawnVector3(std::mt19937& rng, Distribution& d) {
  const double z = d(rng), y = d(rng), x = d(rng);
  return {x, y, z};
}

inline Eigen::Vector3d randomUnit(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return drawnVector3(rng, n).normalized();
}

}  // namespace view_selection::test
