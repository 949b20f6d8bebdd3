// Multi-view triangulation with known, fixed cameras: linear (DLT) initialisation, refinement of
// the reprojection error with Ceres under a Huber loss, and the acceptance tests (cheirality,
// reprojection error, parallax). Used by the feature point source; no ROS, no images.
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <vector>

namespace view_selection::points {

/// A camera with its world-to-camera transform cached.
struct TriangulationCamera {
  core::PinholeIntrinsics intrinsics;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();               ///< O, world
  Eigen::Matrix3d world_to_camera = Eigen::Matrix3d::Identity();  ///< R^T

  static TriangulationCamera from(const core::PinholeIntrinsics& intrinsics,
                                  const core::CameraPose& pose);
  Eigen::Vector3d toCamera(const Eigen::Vector3d& x) const {
    return world_to_camera * (x - centre);
  }
};

/// One pixel observation of a point in camera `camera` (an index into the camera list).
struct PixelObservation {
  int camera = 0;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
};

/// DLT on normalised image coordinates, with the world shifted to the observing centres' mean
/// and scaled by their spread (so millimetre and metre scenes are conditioned alike). Needs at
/// least two observations from distinct centres; returns NaNs when the system is degenerate.
Eigen::Vector3d triangulateLinear(const std::vector<PixelObservation>& observations,
                                  const std::vector<TriangulationCamera>& cameras);

struct RefineOptions {
  double huber_px = 1.0;    ///< Huber loss scale [px]: quadratic below, linear above
  int max_iterations = 20;  ///< Levenberg-Marquardt iterations per point
};

/// Minimises sum Huber(|project(X) - pixel|^2) over each point's observations, cameras fixed,
/// with Ceres (TinySolver, one small problem per point, Huber folded into the residuals).
/// Points with an empty observation list, non-finite values or behind an observing camera are
/// left as they are. Throws InvalidArgument when sizes differ or an observation names no camera.
void refinePoints(std::vector<Eigen::Vector3d>& points,
                  const std::vector<std::vector<PixelObservation>>& observations,
                  const std::vector<TriangulationCamera>& cameras, const RefineOptions& options);

/// Reprojection error [px] of `x` in one observation; +inf when `x` is not in front (z <= 0).
double reprojectionError(const Eigen::Vector3d& x, const PixelObservation& observation,
                         const std::vector<TriangulationCamera>& cameras);

/// Largest angle [deg] at `x` between the rays to the observing cameras' centres.
double maxParallaxDeg(const Eigen::Vector3d& x, const std::vector<PixelObservation>& observations,
                      const std::vector<TriangulationCamera>& cameras);

}  // namespace view_selection::points
