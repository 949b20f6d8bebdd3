#include "view_selection/refine/triangulation.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>

namespace view_selection::refine {

namespace {

constexpr double kPi = 3.14159265358979323846;

/// The DLT point of the observations `use` (normalised rays), then three Gauss-Newton steps on
/// the pixel error. False when the rays meet at infinity or the steps diverge.
bool pointOf(const std::vector<TrackObservation>& track, const std::vector<int>& use, Eigen::Vector3d& x) {
  Eigen::Matrix4d a = Eigen::Matrix4d::Zero();
  for (const int i : use) {
    const TrackObservation& o = track[static_cast<size_t>(i)];
    const Eigen::Vector2d n((o.xy.x() - o.k[2]) / o.k[0], (o.xy.y() - o.k[3]) / o.k[1]);
    Eigen::Matrix<double, 3, 4> pm;
    pm << o.R, o.t;
    const Eigen::RowVector4d r0 = n.x() * pm.row(2) - pm.row(0);
    const Eigen::RowVector4d r1 = n.y() * pm.row(2) - pm.row(1);
    a += r0.transpose() * r0 + r1.transpose() * r1;
  }
  const Eigen::Vector4d h = Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d>(a).eigenvectors().col(0);
  if (!(std::abs(h.w()) > 1e-12 * h.head<3>().norm())) return false;  // at infinity
  x = h.head<3>() / h.w();
  for (int step = 0; step < 3; ++step) {
    Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
    Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
    for (const int i : use) {
      const TrackObservation& o = track[static_cast<size_t>(i)];
      const Eigen::Vector3d p = o.R * x + o.t;
      if (!(p.z() > 0.0)) continue;
      const Eigen::Vector2d res(o.k[0] * p.x() / p.z() + o.k[2] - o.xy.x(), o.k[1] * p.y() / p.z() + o.k[3] - o.xy.y());
      Eigen::Matrix<double, 2, 3> d;
      d << o.k[0] / p.z(), 0.0, -o.k[0] * p.x() / (p.z() * p.z()), 0.0, o.k[1] / p.z(),
          -o.k[1] * p.y() / (p.z() * p.z());
      const Eigen::Matrix<double, 2, 3> j = d * o.R;
      jtj += j.transpose() * j;
      jtr += j.transpose() * res;
    }
    const Eigen::Vector3d dx = (jtj + 1e-12 * Eigen::Matrix3d::Identity()).ldlt().solve(-jtr);
    if (!dx.allFinite()) break;
    x += dx;
  }
  return x.allFinite();
}

}  // namespace

std::pair<double, double> reprojectionError(const TrackObservation& o, const Eigen::Vector3d& x) {
  const Eigen::Vector3d p = o.R * x + o.t;
  const Eigen::Vector2d uv(o.k[0] * p.x() / p.z() + o.k[2], o.k[1] * p.y() / p.z() + o.k[3]);
  return {(uv - o.xy).norm(), p.z()};
}

TriangulatedPoint triangulateTrack(const std::vector<TrackObservation>& track, const TriangulationRule& rule) {
  TriangulatedPoint out;
  std::vector<int> use(track.size());
  for (size_t i = 0; i < track.size(); ++i) use[i] = static_cast<int>(i);
  constexpr double kBehind = std::numeric_limits<double>::infinity();
  for (int round = 0; use.size() >= 2; ++round) {
    if (!pointOf(track, use, out.x)) return out;
    std::vector<double> errors(use.size());
    size_t worst = 0;
    for (size_t q = 0; q < use.size(); ++q) {
      const auto [error, depth] = reprojectionError(track[static_cast<size_t>(use[q])], out.x);
      errors[q] = (depth > 0.0 && std::isfinite(error)) ? error : kBehind;  // behind: the worst
      if (errors[q] > errors[worst]) worst = q;
    }
    if (errors[worst] <= rule.max_error_px) {
      double sum = 0.0;
      for (const double e : errors) sum += e;
      out.mean_error = sum / static_cast<double>(errors.size());
      out.inliers = use;
      break;
    }
    if (round < rule.drop_one_by_one) {
      use.erase(use.begin() + static_cast<long>(worst));
    } else {
      std::vector<int> kept;
      for (size_t q = 0; q < use.size(); ++q)
        if (errors[q] <= rule.max_error_px) kept.push_back(use[q]);
      use = std::move(kept);
    }
  }
  if (out.inliers.size() < 2) return out;
  const double min_angle = rule.min_angle_deg * kPi / 180.0;
  double widest = 0.0;
  for (size_t p = 0; p < out.inliers.size() && widest < min_angle; ++p)
    for (size_t q = p + 1; q < out.inliers.size() && widest < min_angle; ++q) {
      const TrackObservation& a = track[static_cast<size_t>(out.inliers[p])];
      const TrackObservation& b = track[static_cast<size_t>(out.inliers[q])];
      const Eigen::Vector3d ca = -a.R.transpose() * a.t, cb = -b.R.transpose() * b.t;
      const Eigen::Vector3d ra = (ca - out.x).normalized(), rb = (cb - out.x).normalized();
      widest = std::max(widest, std::acos(std::clamp(ra.dot(rb), -1.0, 1.0)));
    }
  out.ok = widest >= min_angle;
  return out;
}

}  // namespace view_selection::refine
