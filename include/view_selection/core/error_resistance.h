// The point error resistance r(P; i -> j) of METHOD.md: how far a 3D point moves when its
// observation in view j is off by one pixel along the epipolar line, with the ray from O_i fixed.
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <limits>
#include <optional>

namespace view_selection {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

/// Unit direction, in pixels, of the epipolar line of view j through pixel `p_j`.
/// `epipole_h` is the homogeneous epipole K_j * (O_i in camera-j coordinates); when its third
/// component is 0 the epipole is at infinity and the direction is that of the projected baseline.
/// Empty when p_j coincides with the epipole (the point lies on the baseline).
std::optional<Eigen::Vector2d> epipolarDirection(const Eigen::Vector3d& epipole_h,
                                                 const Eigen::Vector2d& p_j);

/// Everything r(P; i -> j) needs that does not depend on P, computed once per ordered pair.
/// Points are passed in camera-j coordinates, so the per-point cost is a handful of dot products
/// and two square roots, with no trigonometric call.
class PairErrorResistance {
 public:
  /// `origin_i` is O_i in world coordinates.
  PairErrorResistance(const Eigen::Vector3d& origin_i, const PinholeIntrinsics& intrinsics_j,
                      const CameraPose& pose_j);

  /// r for a point given in camera-j coordinates. +inf when the point is behind camera j, lies on
  /// the baseline, or a perturbed ray does not meet the ray from O_i in front of both cameras.
  double operator()(const Eigen::Vector3d& p_cam_j) const;

  /// O_i in camera-j coordinates.
  const Eigen::Vector3d& originICam() const { return o_i_cam_; }

 private:
  PinholeIntrinsics k_;
  Eigen::Vector3d o_i_cam_;    // O_i in camera-j coordinates (the baseline from O_j)
  Eigen::Vector3d epipole_h_;  // K_j * o_i_cam_
};

/// r(P; i -> j) for a world point, closed form (METHOD.md "Closed form").
double pointErrorResistance(const Eigen::Vector3d& point, const Eigen::Vector3d& origin_i,
                            const PinholeIntrinsics& intrinsics_j, const CameraPose& pose_j);

/// The same quantity by brute force: project P into i, move its projection in j by one pixel
/// along the epipolar line each way, re-triangulate with cv::triangulatePoints (DLT) and take the
/// larger displacement. Slow; the reference the closed form is tested and benchmarked against.
double pointErrorResistanceByTriangulation(const Eigen::Vector3d& point,
                                           const PinholeIntrinsics& intrinsics_i,
                                           const CameraPose& pose_i,
                                           const PinholeIntrinsics& intrinsics_j,
                                           const CameraPose& pose_j);

}  // namespace view_selection
