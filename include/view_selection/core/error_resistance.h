// The point error resistance r(P; i -> j) of METHOD.md: how far a 3D point moves when its
// observation in view j is off by one pixel along the epipolar line, with the ray from O_i fixed.
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <cmath>
#include <cstddef>
#include <limits>
#include <optional>

namespace view_selection::core {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

/// Unit direction, in pixels, of the epipolar line of view j through pixel `p_j`.
/// `epipole_h` is the homogeneous epipole K_j * (O_i in camera-j coordinates); when its third
/// component is 0 the epipole is at infinity and the direction is that of the projected baseline.
/// Empty when p_j coincides with the epipole (the point lies on the baseline).
inline std::optional<Eigen::Vector2d> epipolarDirection(const Eigen::Vector3d& epipole_h,
                                                        const Eigen::Vector2d& p_j) {
  // The line through p_j and the epipole is l = e_h x (p_j, 1); its direction (l_b, -l_a)
  // simplifies to e_z * p_j - e_xy. With e_z = 0 (epipole at infinity) this is -e_xy, the
  // direction of the projected baseline, so one formula covers both cases of METHOD.md.
  const Eigen::Vector2d dir = epipole_h.z() * p_j - epipole_h.head<2>();
  const double norm = dir.norm();
  const double scale = std::abs(epipole_h.z()) * p_j.norm() + epipole_h.head<2>().norm();
  if (!(norm > 1e-12 * scale) || !std::isfinite(norm)) return std::nullopt;
  return Eigen::Vector2d(dir / norm);
}

/// Everything r(P; i -> j) needs that does not depend on P, computed once per ordered pair.
/// Points are passed in camera-j coordinates; each moved ray is intersected with the ray from
/// O_i in closed form (two square roots a point, no trigonometric call).
class PairErrorResistance {
 public:
  /// `origin_i` is O_i in world coordinates.
  PairErrorResistance(const Eigen::Vector3d& origin_i, const PinholeIntrinsics& intrinsics_j,
                      const CameraPose& pose_j);

  /// r for a point given in camera-j coordinates. +inf when the point is behind camera j, lies on
  /// the baseline, or a perturbed ray does not meet the ray from O_i in front of both cameras.
  double operator()(const Eigen::Vector3d& p_cam_j) const;

  /// The same for `count` points in structure-of-arrays form (x[q], y[q], z[q], camera-j
  /// coordinates) into out[q]: the same arithmetic, operation for operation, without branches,
  /// so that the compiler vectorises it and every value equals operator()'s to the last bit.
  void evaluate(const double* x, const double* y, const double* z, std::size_t count,
                double* out) const;

  /// O_i in camera-j coordinates.
  const Eigen::Vector3d& originICam() const { return o_i_cam_; }

 private:
  PinholeIntrinsics k_;
  Eigen::Vector3d o_i_cam_;    // O_i in camera-j coordinates (the baseline from O_j)
  Eigen::Vector3d epipole_h_;  // K_j * o_i_cam_
  double inv_fx_ = 0.0, inv_fy_ = 0.0;
  double epipole_xy_norm_ = 0.0;  // |epipole_h_.head<2>()|
};

/// r(P; i -> j) for a world point, closed form (ray intersection, as PairErrorResistance).
double pointErrorResistance(const Eigen::Vector3d& point, const Eigen::Vector3d& origin_i,
                            const PinholeIntrinsics& intrinsics_j, const CameraPose& pose_j);

/// The same quantity by METHOD.md's sine-law closed form: |PP'_s| = d_j sin(delta_s) /
/// sin(gamma +- delta_s). Independent of the intersection form; used to check it.
double pointErrorResistanceSineLaw(const Eigen::Vector3d& point, const Eigen::Vector3d& origin_i,
                                   const PinholeIntrinsics& intrinsics_j, const CameraPose& pose_j);

}  // namespace view_selection::core
