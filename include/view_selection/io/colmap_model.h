// A COLMAP 3.8 sparse model (cameras.bin, images.bin, points3D.bin): read and written in COLMAP's
// binary format, so that COLMAP's own commands (model_analyzer, point_triangulator, ...) read what
// refine_model writes. Poses are COLMAP's: an image maps world to camera, x_cam = R x + t.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace view_selection::io {

struct ColmapCamera {
  int id = 0;
  int model_id = 1;  ///< COLMAP's model id: 0 SIMPLE_PINHOLE, 1 PINHOLE, 2 SIMPLE_RADIAL, ...
  uint64_t width = 0, height = 0;
  std::vector<double> params;  ///< in COLMAP's order for the model (PINHOLE: fx fy cx cy)
};

/// One 2D point of an image; point3D_id is -1 (kInvalidPoint3DId) when it observes no point.
struct ColmapPoint2D {
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
  int64_t point3D_id = -1;
};

struct ColmapImage {
  int id = 0;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  ///< world -> camera
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();         ///< world -> camera
  int camera_id = 0;
  std::string name;
  std::vector<ColmapPoint2D> points2D;

  /// The camera centre in the world, -R^T t.
  Eigen::Vector3d centre() const { return -(rotation.conjugate() * translation); }
};

struct ColmapTrackElement {
  int image_id = 0;
  int point2D_idx = 0;
};

struct ColmapPoint3D {
  int64_t id = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  std::array<uint8_t, 3> rgb{{0, 0, 0}};
  double error = -1.0;  ///< mean reprojection error [px]; -1 when unknown
  std::vector<ColmapTrackElement> track;
};

struct ColmapModel {
  std::map<int, ColmapCamera> cameras;
  std::map<int, ColmapImage> images;
  std::map<int64_t, ColmapPoint3D> points;

  /// Observations in all tracks.
  size_t observations() const;
  /// Mean of the points' errors, as COLMAP's model_analyzer reports it (0 without points).
  double meanReprojectionError() const;
};

/// Number of parameters of COLMAP's camera model `model_id`; throws core::IoError for an unknown one.
int colmapCameraParameterCount(int model_id);

/// Reads cameras.bin, images.bin and points3D.bin of `folder`. Throws core::IoError naming the
/// file and what is wrong (missing, truncated, a track naming an unknown image, ...).
ColmapModel readColmapModel(const std::string& folder);

/// Writes the three binary files into `folder` (created), each atomically.
void writeColmapModel(const ColmapModel& model, const std::string& folder);

/// The binary model in `from` hard-linked into `folder` (created): the same model without
/// writing it again. False where a link cannot be made (another file system, a name already
/// there, a file system without links), with none of it left in `folder`: the caller writes.
bool linkColmapModel(const std::string& from, const std::string& folder);

}  // namespace view_selection::io
