#include "view_selection/core/triangulation.h"

#include "view_selection/core/exceptions.h"

#include <ceres/ceres.h>
#include <Eigen/SVD>

#include <cmath>
#include <limits>

namespace view_selection {

TriangulationCamera TriangulationCamera::from(const PinholeIntrinsics& intrinsics,
                                              const CameraPose& pose) {
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
  for (const auto& o : observations) mean += cameras.at(static_cast<size_t>(o.camera)).centre;
  mean /= static_cast<double>(observations.size());
  double spread = 0.0;
  for (const auto& o : observations) spread += (cameras[static_cast<size_t>(o.camera)].centre - mean).norm();
  spread /= static_cast<double>(observations.size());
  if (!(spread > 0.0)) return nan;  // all centres equal: no baseline

  Eigen::MatrixXd a(2 * observations.size(), 4);
  for (size_t q = 0; q < observations.size(); ++q) {
    const TriangulationCamera& c = cameras[static_cast<size_t>(observations[q].camera)];
    const Eigen::Vector3d ray = c.intrinsics.backProject(observations[q].pixel);  // normalised
    // P = [R^T | -R^T O] applied to (mean + spread * X', 1) = [spread R^T | R^T (mean - O)].
    Eigen::Matrix<double, 3, 4> p;
    p.leftCols<3>() = spread * c.world_to_camera;
    p.col(3) = c.world_to_camera * (mean - c.centre);
    a.row(static_cast<Eigen::Index>(2 * q)) = ray.x() * p.row(2) - p.row(0);
    a.row(static_cast<Eigen::Index>(2 * q + 1)) = ray.y() * p.row(2) - p.row(1);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullV);
  const Eigen::Vector4d h = svd.matrixV().col(3);
  if (!(std::abs(h.w()) > 1e-12 * h.head<3>().norm())) return nan;  // point at infinity
  return mean + spread * h.head<3>() / h.w();
}

namespace {

struct ReprojectionCost {
  ReprojectionCost(const TriangulationCamera& camera, const Eigen::Vector2d& pixel)
      : r(camera.world_to_camera), t(-camera.world_to_camera * camera.centre),
        fx(camera.intrinsics.fx), fy(camera.intrinsics.fy), cx(camera.intrinsics.cx),
        cy(camera.intrinsics.cy), u(pixel.x()), v(pixel.y()) {}

  template <typename T>
  bool operator()(const T* x, T* residual) const {
    T p[3];
    for (int k = 0; k < 3; ++k) p[k] = T(r(k, 0)) * x[0] + T(r(k, 1)) * x[1] + T(r(k, 2)) * x[2] + T(t[k]);
    if (!(p[2] > T(0.0))) return false;  // behind the camera: reject the step
    residual[0] = T(fx) * p[0] / p[2] + T(cx) - T(u);
    residual[1] = T(fy) * p[1] / p[2] + T(cy) - T(v);
    return true;
  }

  Eigen::Matrix3d r;
  Eigen::Vector3d t;
  double fx, fy, cx, cy, u, v;
};

}  // namespace

void refinePoints(std::vector<Eigen::Vector3d>& points,
                  const std::vector<std::vector<PixelObservation>>& observations,
                  const std::vector<TriangulationCamera>& cameras, const RefineOptions& options) {
  if (points.size() != observations.size())
    throw InvalidArgument("refinePoints: " + std::to_string(points.size()) + " points but " +
                          std::to_string(observations.size()) + " observation lists");
  if (!(options.huber_px > 0.0) || options.max_iterations < 1)
    throw InvalidArgument("refinePoints: huber_px must be > 0 and max_iterations >= 1");
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  // One loss object shared by every residual; the problem must not delete it per residual.
  ceres::HuberLoss loss(options.huber_px);
  bool any = false;
  for (size_t p = 0; p < points.size(); ++p) {
    if (observations[p].empty() || !points[p].allFinite()) continue;
    for (const auto& o : observations[p]) {
      if (o.camera < 0 || static_cast<size_t>(o.camera) >= cameras.size())
        throw InvalidArgument("refinePoints: observation of unknown camera " + std::to_string(o.camera));
      if (cameras[static_cast<size_t>(o.camera)].toCamera(points[p]).z() <= 0.0) continue;
      auto* cost = new ceres::AutoDiffCostFunction<ReprojectionCost, 2, 3>(
          new ReprojectionCost(cameras[static_cast<size_t>(o.camera)], o.pixel));
      problem.AddResidualBlock(cost, &loss, points[p].data());
      any = true;
    }
  }
  if (!any) return;
  ceres::Solver::Options solver;
  // Block-diagonal normal equations (3x3 per point): a sparse Cholesky solves them in linear time.
  solver.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  if (!ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE))
    solver.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
  solver.max_num_iterations = options.max_iterations;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
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
    const Eigen::Vector3d ra = (cameras.at(static_cast<size_t>(observations[a].camera)).centre - x).normalized();
    for (size_t b = a + 1; b < observations.size(); ++b) {
      const Eigen::Vector3d rb = (cameras.at(static_cast<size_t>(observations[b].camera)).centre - x).normalized();
      best = std::max(best, std::atan2(ra.cross(rb).norm(), ra.dot(rb)));
    }
  }
  return best * 180.0 / M_PI;
}

}  // namespace view_selection
