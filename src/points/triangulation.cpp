#include "view_selection/points/triangulation.h"

#include "view_selection/core/exceptions.h"

#include <ceres/tiny_solver.h>
#include <ceres/tiny_solver_autodiff_function.h>
#include <Eigen/Eigenvalues>

#include <cmath>
#include <limits>

namespace view_selection::points {

TriangulationCamera TriangulationCamera::from(const core::PinholeIntrinsics& intrinsics,
                                              const core::CameraPose& pose) {
  TriangulationCamera c;
  c.intrinsics = intrinsics;
  c.centre = pose.position;
  c.world_to_camera = pose.rotation().transpose();
  return c;
}

Eigen::Vector3d triangulateLinear(const std::vector<PixelObservation>& observations,
                                  const std::vector<TriangulationCamera>& cameras) {
  const Eigen::Vector3d nan = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  if (observations.size() < 2) return nan;
  // Normalise the world: centre on the observing cameras, unit mean distance from it.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& o : observations) {
    if (o.camera < 0 || static_cast<size_t>(o.camera) >= cameras.size())
      throw core::InvalidArgument("triangulateLinear: observation of unknown camera " +
                                  std::to_string(o.camera));
    mean += cameras[static_cast<size_t>(o.camera)].centre;
  }
  mean /= static_cast<double>(observations.size());
  double spread = 0.0;
  for (const auto& o : observations)
    spread += (cameras[static_cast<size_t>(o.camera)].centre - mean).norm();
  spread /= static_cast<double>(observations.size());
  if (!(spread > 0.0)) return nan;  // all centres equal: no baseline

  // Least squares on the stacked DLT rows: the eigenvector of A^T A with the smallest
  // eigenvalue (4x4, so no SVD of a tall matrix per point).
  Eigen::Matrix4d ata = Eigen::Matrix4d::Zero();
  for (const auto& o : observations) {
    const TriangulationCamera& c = cameras[static_cast<size_t>(o.camera)];
    const Eigen::Vector3d ray = c.intrinsics.backProject(o.pixel);  // normalised
    // P = [R^T | -R^T O] applied to (mean + spread * X', 1) = [spread R^T | R^T (mean - O)].
    Eigen::Matrix<double, 3, 4> p;
    p.leftCols<3>() = spread * c.world_to_camera;
    p.col(3) = c.world_to_camera * (mean - c.centre);
    const Eigen::RowVector4d r0 = ray.x() * p.row(2) - p.row(0);
    const Eigen::RowVector4d r1 = ray.y() * p.row(2) - p.row(1);
    ata += r0.transpose() * r0 + r1.transpose() * r1;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eigen(ata);
  const Eigen::Vector4d h = eigen.eigenvectors().col(0);            // eigenvalues ascending
  if (!(std::abs(h.w()) > 1e-12 * h.head<3>().norm())) return nan;  // point at infinity
  return mean + spread * h.head<3>() / h.w();
}

namespace {

/// All observations of one point; residuals are the reprojection errors scaled so that their
/// squared norm is the Huber cost rho(s) of each observation (s = squared pixel error):
/// rho(s) = s for s <= delta^2, 2 delta sqrt(s) - delta^2 beyond. Minimising the sum of squares
/// of these residuals is minimising the robust cost exactly (rho is continuously differentiable,
/// so the scaled residual is too, and Gauss-Newton on it is well defined).
struct TrackReprojectionCost {
  static constexpr double kBehindCamera = 1e8;  ///< [px] residual of a point behind a camera
  const std::vector<PixelObservation>* observations;
  const std::vector<TriangulationCamera>* cameras;
  double delta;

  int NumResiduals() const { return 2 * static_cast<int>(observations->size()); }

  template <typename T>
  bool operator()(const T* x, T* residual) const {
    using std::sqrt;
    for (size_t q = 0; q < observations->size(); ++q) {
      const PixelObservation& o = (*observations)[q];
      const TriangulationCamera& c = (*cameras)[static_cast<size_t>(o.camera)];
      const Eigen::Matrix3d& r = c.world_to_camera;
      T p[3];
      for (int k = 0; k < 3; ++k)
        p[k] = T(r(k, 0)) * (x[0] - T(c.centre.x())) + T(r(k, 1)) * (x[1] - T(c.centre.y())) +
               T(r(k, 2)) * (x[2] - T(c.centre.z()));
      if (!(p[2] > T(0.0))) {
        // Behind the camera: the step must be rejected. TinySolver ignores the return value of
        // a trial step's evaluation and compares the residuals' norm, so every residual is set
        // (to a cost no step in front reaches): otherwise it compared whatever the buffer held
        // before, and the result depended on the heap's contents.
        for (size_t i = 0; i < 2 * observations->size(); ++i) residual[i] = T(kBehindCamera);
        return false;
      }
      const T du = T(c.intrinsics.fx) * p[0] / p[2] + T(c.intrinsics.cx) - T(o.pixel.x());
      const T dv = T(c.intrinsics.fy) * p[1] / p[2] + T(c.intrinsics.cy) - T(o.pixel.y());
      const T s = du * du + dv * dv;
      T scale(1.0);
      if (s > T(delta * delta)) {
        const T norm = sqrt(s);
        scale = sqrt(T(2.0 * delta) * norm - T(delta * delta)) / norm;
      }
      residual[2 * q] = du * scale;
      residual[2 * q + 1] = dv * scale;
    }
    return true;
  }
};

}  // namespace

void refinePoints(std::vector<Eigen::Vector3d>& points,
                  const std::vector<std::vector<PixelObservation>>& observations,
                  const std::vector<TriangulationCamera>& cameras, const RefineOptions& options) {
  if (points.size() != observations.size())
    throw core::InvalidArgument("refinePoints: " + std::to_string(points.size()) + " points but " +
                                std::to_string(observations.size()) + " observation lists");
  if (!(options.huber_px > 0.0) || options.max_iterations < 1)
    throw core::InvalidArgument("refinePoints: huber_px must be > 0 and max_iterations >= 1");
  for (const auto& list : observations)
    for (const auto& o : list)
      if (o.camera < 0 || static_cast<size_t>(o.camera) >= cameras.size())
        throw core::InvalidArgument("refinePoints: observation of unknown camera " +
                                    std::to_string(o.camera));
  // Ceres' TinySolver (Levenberg-Marquardt for small dense problems): each point is independent
  // (cameras fixed), and one general ceres::Problem per point, or one for all, spends 20-60x
  // longer in set-up than in solving 3 unknowns.
  using Function = ceres::TinySolverAutoDiffFunction<TrackReprojectionCost, Eigen::Dynamic, 3>;
  for (size_t p = 0; p < points.size(); ++p) {
    if (observations[p].empty() || !points[p].allFinite()) continue;
    bool in_front = true;
    for (const auto& o : observations[p])
      in_front = in_front && cameras[static_cast<size_t>(o.camera)].toCamera(points[p]).z() > 0.0;
    if (!in_front) continue;  // the cost is undefined at the start; cheirality rejects it anyway
    const TrackReprojectionCost cost{&observations[p], &cameras, options.huber_px};
    Function function(cost);
    ceres::TinySolver<Function> solver;
    solver.options.max_num_iterations = options.max_iterations;
    Eigen::Vector3d x = points[p];
    solver.Solve(function, &x);
    if (x.allFinite()) points[p] = x;
  }
}

double reprojectionError(const Eigen::Vector3d& x, const PixelObservation& observation,
                         const std::vector<TriangulationCamera>& cameras) {
  const TriangulationCamera& c = cameras.at(static_cast<size_t>(observation.camera));
  const Eigen::Vector3d p = c.toCamera(x);
  if (!(p.z() > 0.0)) return std::numeric_limits<double>::infinity();
  return (c.intrinsics.project(p) - observation.pixel).norm();
}

double maxParallaxDeg(const Eigen::Vector3d& x, const std::vector<PixelObservation>& observations,
                      const std::vector<TriangulationCamera>& cameras) {
  double best = 0.0;
  for (size_t a = 0; a < observations.size(); ++a) {
    const Eigen::Vector3d ra =
        (cameras.at(static_cast<size_t>(observations[a].camera)).centre - x).normalized();
    for (size_t b = a + 1; b < observations.size(); ++b) {
      const Eigen::Vector3d rb =
          (cameras.at(static_cast<size_t>(observations[b].camera)).centre - x).normalized();
      best = std::max(best, std::atan2(ra.cross(rb).norm(), ra.dot(rb)));
    }
  }
  return best * 180.0 / M_PI;
}

}  // namespace view_selection::points
