#include "view_selection/eval/trajectory_alignment.h"

#include "view_selection/core/exceptions.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

namespace view_selection::eval {

SimilarityTransform alignUmeyama(const Eigen::Matrix3Xd& estimated,
                                 const Eigen::Matrix3Xd& ground_truth,
                                 const AlignmentConfig& config) {
  if (estimated.cols() != ground_truth.cols())
    throw core::InvalidArgument("trajectory alignment: " + std::to_string(estimated.cols()) +
                                " estimated positions but " + std::to_string(ground_truth.cols()) +
                                " ground-truth positions");
  const Eigen::Index n = estimated.cols();
  if (n < 3)
    throw core::InvalidArgument("trajectory alignment: needs at least 3 matched positions, got " +
                                std::to_string(n));
  if (!estimated.allFinite() || !ground_truth.allFinite())
    throw core::InvalidArgument("trajectory alignment: a position is not finite");

  const Eigen::Vector3d mu_e = estimated.rowwise().mean();
  const Eigen::Vector3d mu_g = ground_truth.rowwise().mean();
  const Eigen::Matrix3Xd e = estimated.colwise() - mu_e;
  const Eigen::Matrix3Xd g = ground_truth.colwise() - mu_g;

  // Both point sets must span at least a plane: collinear points leave a rotation about the line
  // free.
  for (const auto* set : {&e, &g}) {
    const Eigen::JacobiSVD<Eigen::Matrix3d> spread(*set * set->transpose() /
                                                   static_cast<double>(n));
    const Eigen::Vector3d s = spread.singularValues();
    const char* which = set == &e ? "estimated" : "ground-truth";
    if (!(s(0) > 0.0))
      throw core::InvalidArgument(std::string("trajectory alignment: the ") + which +
                                  " positions all coincide");
    if (std::sqrt(s(1) / s(0)) <= config.min_relative_spread)
      throw core::InvalidArgument(std::string("trajectory alignment: the ") + which +
                                  " positions are collinear; a similarity is not determined");
  }

  const double n_d = static_cast<double>(n);
  const Eigen::Matrix3d sigma = g * e.transpose() / n_d;  // covariance gt x est
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sigma, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d s_fix = Eigen::Matrix3d::Identity();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0)
    s_fix(2, 2) = -1.0;  // no reflection

  SimilarityTransform t;
  t.rotation = svd.matrixU() * s_fix * svd.matrixV().transpose();
  if (config.with_scale) {
    const double var_e = e.squaredNorm() / n_d;
    t.scale = (svd.singularValues().asDiagonal() * s_fix).trace() / var_e;
  }
  t.translation = mu_g - t.scale * (t.rotation * mu_e);
  return t;
}

TrajectoryError absoluteTrajectoryError(const Eigen::Matrix3Xd& estimated,
                                        const Eigen::Matrix3Xd& ground_truth,
                                        const AlignmentConfig& config) {
  TrajectoryError r;
  r.alignment = alignUmeyama(estimated, ground_truth, config);
  r.count = static_cast<size_t>(estimated.cols());
  double sum = 0.0, sum_sq = 0.0;
  for (Eigen::Index i = 0; i < estimated.cols(); ++i) {
    const double d = (ground_truth.col(i) - r.alignment.apply(estimated.col(i))).norm();
    r.errors.push_back(d);
    sum += d;
    sum_sq += d * d;
    r.max = std::max(r.max, d);
  }
  r.mean = sum / static_cast<double>(r.count);
  r.rmse = std::sqrt(sum_sq / static_cast<double>(r.count));
  std::vector<double> sorted = r.errors;
  std::sort(sorted.begin(), sorted.end());
  const size_t m = sorted.size() / 2;
  r.median = sorted.size() % 2 ? sorted[m] : 0.5 * (sorted[m - 1] + sorted[m]);
  return r;
}

std::vector<ColmapImagePose> readColmapImagesTxt(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw core::IoError("cannot read COLMAP images file '" + path + "'");
  std::vector<ColmapImagePose> images;
  std::string line;
  size_t line_no = 0;
  bool expect_points = false;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!line.empty() && line[0] == '#') continue;
    if (expect_points) {  // the 2D points line may be empty (an image without observations)
      expect_points = false;
      continue;
    }
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    std::istringstream s(line);
    ColmapImagePose im;
    int camera_id = 0;
    double q[4], tv[3];
    if (!(s >> im.image_id >> q[0] >> q[1] >> q[2] >> q[3] >> tv[0] >> tv[1] >> tv[2] >> camera_id))
      throw core::IoError(path + ":" + std::to_string(line_no) +
                          ": expected 'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME'");
    std::getline(s >> std::ws, im.name);
    if (im.name.empty())
      throw core::IoError(path + ":" + std::to_string(line_no) + ": image without a name");
    im.qvec_wxyz = Eigen::Vector4d(q[0], q[1], q[2], q[3]);
    im.tvec = Eigen::Vector3d(tv[0], tv[1], tv[2]);
    const double norm = im.qvec_wxyz.norm();
    if (!im.qvec_wxyz.allFinite() || !im.tvec.allFinite() || std::abs(norm - 1.0) > 0.05)
      throw core::IoError(path + ":" + std::to_string(line_no) +
                          ": pose is not finite or the quaternion is not unit");
    const Eigen::Matrix3d r_cw =
        Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
    im.centre = -r_cw.transpose() * im.tvec;
    images.push_back(im);
    expect_points = true;
  }
  return images;
}

}  // namespace view_selection::eval
