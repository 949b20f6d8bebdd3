#include "view_selection/eval/reference_error_resistance.h"

#include "view_selection/core/error_resistance.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>

namespace view_selection::eval {

using core::CameraPose;
using core::PinholeIntrinsics;

namespace {

cv::Matx34d projectionMatrix(const core::PinholeIntrinsics& k, const core::CameraPose& pose) {
  const Eigen::Matrix3d r_cw = pose.rotation().transpose();
  const Eigen::Vector3d t_cw = -r_cw * pose.position;
  Eigen::Matrix<double, 3, 4> rt;
  rt << r_cw, t_cw;
  const Eigen::Matrix<double, 3, 4> p = k.matrix() * rt;
  cv::Matx34d out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) out(r, c) = p(r, c);
  return out;
}

}  // namespace

double pointErrorResistanceByTriangulation(const Eigen::Vector3d& point,
                                           const core::PinholeIntrinsics& intrinsics_i,
                                           const core::CameraPose& pose_i,
                                           const core::PinholeIntrinsics& intrinsics_j,
                                           const core::CameraPose& pose_j) {
  const Eigen::Vector3d p_cam_i = pose_i.worldToCamera(point);
  const Eigen::Vector3d p_cam_j = pose_j.worldToCamera(point);
  if (!(p_cam_i.z() > 0.0) || !(p_cam_j.z() > 0.0)) return core::kInfinity;
  const Eigen::Vector2d p_i = intrinsics_i.project(p_cam_i);
  const Eigen::Vector2d p_j = intrinsics_j.project(p_cam_j);
  const Eigen::Vector3d epipole_h = intrinsics_j.matrix() * pose_j.worldToCamera(pose_i.position);
  const std::optional<Eigen::Vector2d> u = core::epipolarDirection(epipole_h, p_j);
  if (!u) return core::kInfinity;

  const cv::Matx34d proj_i = projectionMatrix(intrinsics_i, pose_i);
  const cv::Matx34d proj_j = projectionMatrix(intrinsics_j, pose_j);
  double worst = 0.0;
  for (const double s : {1.0, -1.0}) {
    const Eigen::Vector2d moved = p_j + s * *u;
    cv::Mat pts_i = (cv::Mat_<double>(2, 1) << p_i.x(), p_i.y());
    cv::Mat pts_j = (cv::Mat_<double>(2, 1) << moved.x(), moved.y());
    cv::Mat homogeneous;
    cv::triangulatePoints(proj_i, proj_j, pts_i, pts_j, homogeneous);
    homogeneous.convertTo(homogeneous, CV_64F);
    const double w = homogeneous.at<double>(3, 0);
    if (!(std::abs(w) > 1e-15)) return core::kInfinity;
    const Eigen::Vector3d moved_point(homogeneous.at<double>(0, 0) / w,
                                      homogeneous.at<double>(1, 0) / w,
                                      homogeneous.at<double>(2, 0) / w);
    // The intersection must lie on the ray from O_i (t > 0) and in front of camera j.
    if (!((moved_point - pose_i.position).dot(point - pose_i.position) > 0.0))
      return core::kInfinity;
    if (!(pose_j.worldToCamera(moved_point).z() > 0.0)) return core::kInfinity;
    worst = std::max(worst, (moved_point - point).norm());
  }
  return worst;
}

}  // namespace view_selection::eval
