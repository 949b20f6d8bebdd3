#include "view_selection/core/error_resistance.h"

#include "view_selection/core/sanitizers.h"

#include <limits>

#include <algorithm>
#include <cmath>

// The evaluation loop is compiled twice, for AVX2 and for any x86-64, and the loader picks one
// through an ifunc. ThreadSanitizer cannot have ifuncs: their resolvers run before its runtime
// is set up, and every program then crashes at start. Under TSan the loop is compiled once.
#if VS_THREAD_SANITIZER
#define VS_TARGET_CLONES
#else
#define VS_TARGET_CLONES __attribute__((target_clones("avx2", "default")))
#endif

namespace view_selection::core {

PairErrorResistance::PairErrorResistance(const Eigen::Vector3d& origin_i,
                                         const PinholeIntrinsics& intrinsics_j,
                                         const CameraPose& pose_j)
    : k_(intrinsics_j), o_i_cam_(pose_j.worldToCamera(origin_i)) {
  epipole_h_ = k_.matrix() * o_i_cam_;
  inv_fx_ = 1.0 / k_.fx;
  inv_fy_ = 1.0 / k_.fy;
  epipole_xy_norm_ = epipole_h_.head<2>().norm();
}

namespace {

/// One point of PairErrorResistance::evaluate, written out in scalars in the order of
/// operations Eigen uses for operator() (cross products component by component, dot products
/// and squared norms summed left to right), so both give the same bits.
struct PairConstants {
  double fx, fy, cx, cy, inv_fx, inv_fy;
  double bx, by, bz;       // O_i in camera j
  double ex, ey, ez;       // the homogeneous epipole
  double abs_ez, exy_norm;
};

inline double resistance(const PairConstants& c, double px, double py, double pz) {
  const double kInf = std::numeric_limits<double>::infinity();
  bool valid = pz > 0.0;  // behind camera j (also NaN)
  const double inv_z = 1.0 / pz;
  const double uj = c.fx * px * inv_z + c.cx;
  const double vj = c.fy * py * inv_z + c.cy;
  // epipolarDirection: dir = e_z * p_j - e_xy, unit; none when p_j is the epipole.
  const double dx = c.ez * uj - c.ex, dy = c.ez * vj - c.ey;
  const double norm = std::sqrt(dx * dx + dy * dy);
  const double scale = c.abs_ez * std::sqrt(uj * uj + vj * vj) + c.exy_norm;
  // `&` not `&&`: no branch, so the loop over points vectorises.
  valid = valid & (norm > 1e-12 * scale) & (norm <= std::numeric_limits<double>::max());
  const double ux = dx / norm, uy = dy / norm;
  const double ax = px - c.bx, ay = py - c.by, az = pz - c.bz;  // O_i -> P
  double worst = 0.0;
  for (int k = 0; k < 2; ++k) {
    const double sgn = k == 0 ? 1.0 : -1.0;
    const double rx = (uj + sgn * ux - c.cx) * c.inv_fx;  // the ray through p'_j
    const double ry = (vj + sgn * uy - c.cy) * c.inv_fy;
    const double rz = 1.0;
    const double nx = ay * rz - az * ry, ny = az * rx - ax * rz, nz = ax * ry - ay * rx;  // a x d
    const double nn = nx * nx + ny * ny + nz * nz;
    const double mx = c.by * rz - c.bz * ry, my = c.bz * rx - c.bx * rz, mz = c.bx * ry - c.by * rx;  // b x d
    const double t = -(mx * nx + my * ny + mz * nz) / nn;
    valid = valid & (nn > 1e-300) & (t > 0.0) & (c.bz + t * az > 0.0);
    const double moved = std::abs(t - 1.0);
    worst = moved > worst ? moved : worst;
  }
  const double r = worst * std::sqrt(ax * ax + ay * ay + az * az);
  return valid & (r <= std::numeric_limits<double>::max()) ? r : kInf;
}

VS_TARGET_CLONES void evaluateAll(
    const PairConstants& c, const double* __restrict x, const double* __restrict y,
    const double* __restrict z, std::size_t count, double* __restrict out) {
  for (std::size_t q = 0; q < count; ++q) out[q] = resistance(c, x[q], y[q], z[q]);
}

}  // namespace

void PairErrorResistance::evaluate(const double* x, const double* y, const double* z,
                                   std::size_t count, double* out) const {
  const PairConstants c{k_.fx,         k_.fy,         k_.cx,          k_.cy,       inv_fx_,
                        inv_fy_,       o_i_cam_.x(),  o_i_cam_.y(),   o_i_cam_.z(), epipole_h_.x(),
                        epipole_h_.y(), epipole_h_.z(), std::abs(epipole_h_.z()), epipole_xy_norm_};
  evaluateAll(c, x, y, z, count, out);
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
