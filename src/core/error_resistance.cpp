#include "view_selection/core/error_resistance.h"

#include <algorithm>
#include <cmath>

namespace view_selection::core {

PairErrorResistance::PairErrorResistance(const Eigen::Vector3d& origin_i,
                                         const PinholeIntrinsics& intrinsics_j,
                                         const CameraPose& pose_j)
    : k_(intrinsics_j), o_i_cam_(pose_j.worldToCamera(origin_i)) {
  epipole_h_ = k_.matrix() * o_i_cam_;
  inv_fx_ = 1.0 / k_.fx;
  inv_fy_ = 1.0 / k_.fy;
}

double PairErrorResistance::operator()(const Eigen::Vector3d& p_cam) const {
  // METHOD.md step 3 done directly: intersect the moved ray O_j + l d' with the fixed ray
  // O_i + t (P - O_i), all in camera-j coordinates (O_j = 0). Both lie in the epipolar plane,
  // so t = ((O_j - O_i) x d') . (a x d') / |a x d'|^2 is exact, and |P P'| = |t - 1| |a|.
  // Two square roots per point; the sine-law form (pointErrorResistanceSineLaw) is the same
  // quantity and is kept as an independent check.
  if (!(p_cam.z() > 0.0)) return kInfinity;  // behind camera j (also catches NaN)
  const double inv_z = 1.0 / p_cam.z();
  const Eigen::Vector2d p_j(k_.fx * p_cam.x() * inv_z + k_.cx, k_.fy * p_cam.y() * inv_z + k_.cy);
  const std::optional<Eigen::Vector2d> u = epipolarDirection(epipole_h_, p_j);
  if (!u) return kInfinity;  // P on the baseline: no parallax

  const Eigen::Vector3d& b = o_i_cam_;  // O_i
  const Eigen::Vector3d a = p_cam - b;  // O_i -> P
  double worst_t = 0.0;                 // largest |t - 1|
  for (const double s : {1.0, -1.0}) {
    const Eigen::Vector3d d((p_j.x() + s * u->x() - k_.cx) * inv_fx_,
                            (p_j.y() + s * u->y() - k_.cy) * inv_fy_, 1.0);  // ray through p'_j
    const Eigen::Vector3d n = a.cross(d);
    const double nn = n.squaredNorm();
    if (!(nn > 1e-300)) return kInfinity;  // parallel rays
    const double t = -b.cross(d).dot(n) / nn;
    if (!(t > 0.0)) return kInfinity;                  // behind O_i
    if (!(b.z() + t * a.z() > 0.0)) return kInfinity;  // behind camera j (l = depth of P')
    worst_t = std::max(worst_t, std::abs(t - 1.0));
  }
  const double r = worst_t * a.norm();
  return std::isfinite(r) ? r : kInfinity;
}

double pointErrorResistanceSineLaw(const Eigen::Vector3d& point, const Eigen::Vector3d& origin_i,
                                   const PinholeIntrinsics& k, const CameraPose& pose_j) {
  const Eigen::Vector3d p_cam = pose_j.worldToCamera(point);
  if (!(p_cam.z() > 0.0)) return kInfinity;
  const Eigen::Vector3d b = pose_j.worldToCamera(origin_i);  // O_j -> O_i
  const Eigen::Vector2d p_j = k.project(p_cam);
  const std::optional<Eigen::Vector2d> u = epipolarDirection(k.matrix() * b, p_j);
  if (!u) return kInfinity;

  // Triangle O_i, P, O_j in camera-j coordinates (O_j at the origin).
  const Eigen::Vector3d& d = p_cam;  // O_j -> P
  const double d_norm = d.norm();
  const double b_norm = b.norm();
  const Eigen::Vector3d to_oi = b - d;  // P -> O_i
  const double to_oi_norm = to_oi.norm();
  if (!(b_norm > 0.0) || !(to_oi_norm > 0.0)) return kInfinity;
  // Parallax angle gamma at P between P->O_i and P->O_j = -d; angle beta at O_j.
  const double cos_gamma = -to_oi.dot(d) / (to_oi_norm * d_norm);
  const double sin_gamma = to_oi.cross(d).norm() / (to_oi_norm * d_norm);
  const double cos_beta = d.dot(b) / (d_norm * b_norm);
  const double sin_beta = d.cross(b).norm() / (d_norm * b_norm);

  double worst = 0.0;
  for (const double s : {1.0, -1.0}) {
    const Eigen::Vector3d d_moved = k.backProject(p_j + s * *u);  // ray through p'_j
    const double moved_norm = d_moved.norm();
    const double cos_delta = d.dot(d_moved) / (d_norm * moved_norm);
    const double sin_delta = d.cross(d_moved).norm() / (d_norm * moved_norm);
    // Turns towards O_i when its component along b's part orthogonal to d is positive.
    const bool towards = d_moved.dot(b) * d_norm * d_norm - d.dot(b) * d_moved.dot(d) > 0.0;
    double denominator;
    if (towards) {
      // Meets the ray from O_i between O_i and P only while delta < beta; beyond, behind O_i.
      if (!(sin_beta * cos_delta - cos_beta * sin_delta > 0.0)) return kInfinity;
      denominator = sin_gamma * cos_delta + cos_gamma * sin_delta;  // sin(gamma + delta)
    } else {
      denominator = sin_gamma * cos_delta - cos_gamma * sin_delta;  // sin(gamma - delta)
    }
    if (!(denominator > 0.0)) return kInfinity;  // gamma <= delta: the rays do not meet
    worst = std::max(worst, d_norm * sin_delta / denominator);
  }
  return std::isfinite(worst) ? worst : kInfinity;
}

double pointErrorResistance(const Eigen::Vector3d& point, const Eigen::Vector3d& origin_i,
                            const PinholeIntrinsics& intrinsics_j, const CameraPose& pose_j) {
  const PairErrorResistance pair(origin_i, intrinsics_j, pose_j);
  return pair(pose_j.worldToCamera(point));
}

}  // namespace view_selection::core
