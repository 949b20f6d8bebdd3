// Absolute trajectory error: a similarity (Sim(3)) alignment of estimated camera centres to ground
// truth by Umeyama's closed form, then the residual statistics. Used to score reconstructions
// (COLMAP's, for the evaluation against the paper) whose scale and frame are arbitrary.
#pragma once

#include <Eigen/Core>

#include <string>
#include <vector>

namespace view_selection::eval {

/// gt ≈ scale * rotation * estimated + translation.
struct SimilarityTransform {
  double scale = 1.0;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d apply(const Eigen::Vector3d& p) const {
    return scale * (rotation * p) + translation;
  }
};

struct TrajectoryError {
  SimilarityTransform alignment;  ///< estimated -> ground truth
  size_t count = 0;               ///< matched positions used
  double rmse = 0.0;              ///< ATE: sqrt(mean |gt - aligned|^2), ground-truth units
  double mean = 0.0;
  double median = 0.0;  ///< mean of the two middle values for an even count
  double max = 0.0;
  std::vector<double> errors;  ///< |gt_i - aligned_i|, in input order
};

struct AlignmentConfig {
  bool with_scale = true;  ///< false: SE(3) only (scale fixed at 1)
  /// Degeneracy gate: the second singular value of the centred point spread, relative to the
  /// largest, must exceed this (collinear or coincident points cannot fix a rotation).
  double min_relative_spread = 1e-9;
};

/// Umeyama's least-squares similarity from `estimated` to `ground_truth` (columns are matched
/// points). Throws InvalidArgument for different counts, fewer than 3 points, non-finite values,
/// or points that are (numerically) coincident or collinear, with a message saying which.
SimilarityTransform alignUmeyama(const Eigen::Matrix3Xd& estimated,
                                 const Eigen::Matrix3Xd& ground_truth,
                                 const AlignmentConfig& config = {});

/// alignUmeyama, then the residuals |gt_i - T(est_i)| and their statistics.
TrajectoryError absoluteTrajectoryError(const Eigen::Matrix3Xd& estimated,
                                        const Eigen::Matrix3Xd& ground_truth,
                                        const AlignmentConfig& config = {});

/// One registered image of a COLMAP text model (images.txt): its name and camera centre.
struct ColmapImagePose {
  int image_id = 0;
  std::string name;           ///< relative to COLMAP's --image_path
  Eigen::Vector3d centre;     ///< -R^T t, model units
  Eigen::Vector4d qvec_wxyz;  ///< world-to-camera rotation, as written
  Eigen::Vector3d tvec;       ///< world-to-camera translation, as written
};

/// Reads COLMAP's images.txt (text model; `colmap model_converter --output_type TXT`). Each image
/// is two lines, the second (2D points) is skipped. Throws IoError naming the file and line for
/// a missing file or a malformed line. Returned in file order.
std::vector<ColmapImagePose> readColmapImagesTxt(const std::string& path);

}  // namespace view_selection::eval
