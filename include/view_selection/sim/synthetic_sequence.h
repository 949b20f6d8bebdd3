// The built-in synthetic sequence: a textured box room with furniture-like boxes, seen by a
// handheld-like camera walking a loop, rendered by ray casting into colour, TUM depth and exact
// poses. Deterministic from a seed (same seed and options: byte-identical files). It is the demo's
// default input and the tests' source of exact ground truth (analytic surfaces, exact poses).
#pragma once

#include "view_selection/core/types.h"
#include "view_selection/io/tum_dataset.h"

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace view_selection::sim {

// ---------------------------------------------------------------------------------------------
// Scene

/// An oriented box: the room (seen from inside) or an object (seen from outside). World frame:
/// z up, the floor at z = 0, the room centred on x = y = 0.
struct SceneBox {
  std::string name;                                     ///< "room", "table top", "box 3", ...
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();     ///< [m]
  Eigen::Vector3d half_size = Eigen::Vector3d::Ones();  ///< half extents along its own axes [m]
  double yaw = 0.0;                                     ///< rotation about world z [rad]
  bool inside = false;  ///< true for the room: rays hit it from within
};

struct SyntheticSceneConfig {
  Eigen::Vector3d room_size{6.0, 5.0, 3.0};  ///< x, y, z extent of the room [m]
  int wall_objects = 8;             ///< boxes standing along the walls (cabinets, crates, shelves)
  bool table = true;                ///< a table (top and four legs) with a box on it, in the middle
  double texels_per_metre = 250.0;  ///< texture resolution on every surface

  /// Throws InvalidArgument naming the bad value.
  void validate() const;
};

/// Where a ray meets the scene.
struct SurfaceHit {
  double t = 0.0;  ///< ray parameter: point = origin + t * direction
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  ///< unit, towards the side the ray came from
  int box = -1;                                      ///< index into SyntheticScene::boxes()
  int face = -1;  ///< 0..5: -x, +x, -y, +y, -z, +z of the box's own axes
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();  ///< position on the face [m], from its corner
};

/// The room and its objects, with a procedural texture on every face (random blobs, polygons and
/// strokes at many scales and contrasts, so corner detectors find many distinctive points).
class SyntheticScene {
 public:
  explicit SyntheticScene(uint64_t seed, const SyntheticSceneConfig& config = {});

  const SyntheticSceneConfig& config() const { return config_; }
  /// boxes()[0] is the room; the objects follow. Objects do not overlap each other.
  const std::vector<SceneBox>& boxes() const { return boxes_; }

  /// Nearest surface along origin + t * direction with t in (0, max_t]; the direction need not
  /// be unit length (t is then in its units). Empty when nothing is hit.
  std::optional<SurfaceHit> castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                                    double max_t) const;
  /// The same, against the listed boxes only (indices into boxes(), e.g. from boxesInView).
  std::optional<SurfaceHit> castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                                    double max_t, const std::vector<int>& among) const;
  /// Boxes that may appear in the image of a camera at `pose` (bounding spheres against the
  /// view frustum; conservative), in ascending order. Rendering casts only against these.
  std::vector<int> boxesInView(const core::CameraPose& pose,
                               const core::PinholeIntrinsics& intrinsics) const;
  /// Exact Euclidean distance from `p` to the nearest surface of any box (room walls included).
  double distanceToSurface(const Eigen::Vector3d& p) const;
  /// True when `p` is inside the room and outside every object, at least `margin` from all.
  bool isFree(const Eigen::Vector3d& p, double margin = 0.0) const;
  /// Texture colour (BGR, 0..1) at a hit, pre-filtered for a footprint of `footprint` metres
  /// (the size of one image pixel on the surface), so distant surfaces do not alias.
  Eigen::Vector3f albedo(const SurfaceHit& hit, double footprint) const;

 private:
  struct FaceTexture {
    std::vector<cv::Mat> levels;  ///< CV_8UC3 (BGR) mip pyramid, level 0 full resolution
  };
  const FaceTexture& texture(int box, int face) const {
    return textures_[static_cast<size_t>(box) * 6 + static_cast<size_t>(face)];
  }

  SyntheticSceneConfig config_;
  std::vector<SceneBox> boxes_;
  std::vector<Eigen::Vector2d> yaw_cos_sin_;  ///< of every box's yaw, for fast ray casting
  std::vector<int> all_boxes_;                ///< 0, 1, ..., boxes_.size() - 1
  std::vector<FaceTexture> textures_;
};

// ---------------------------------------------------------------------------------------------
// Sequence

/// The default pinhole camera (525 px focal length at 640 x 480, the Kinect's), scaled to another
/// image size: focal length with the width, principal point at the image centre.
core::PinholeIntrinsics syntheticIntrinsics(int width = 640, int height = 480);

struct SyntheticSequenceConfig {
  uint64_t seed = 1;  ///< textures, object layout, path phases and noise
  int frames = 300;
  core::PinholeIntrinsics intrinsics = syntheticIntrinsics();
  double fps = 30.0;            ///< frame rate [Hz]
  double speed = 0.7;           ///< walking speed along the loop [m/s]
  double start_stamp = 1000.0;  ///< stamp of frame 0 [s]
  double noise_sigma = 2.0;     ///< colour noise [8-bit grey levels]; 0 for none
  double max_range = 8.0;       ///< depth beyond this is 0 (no surface) [m]; at most 13.1
  SyntheticSceneConfig scene;
  /// A photo collection instead of the walk: `frames` views on a ring (or arc) around the box on
  /// the table, `ring_step_deg` apart in azimuth, each looking at the box's centre from
  /// `ring_distance` [m] and `ring_elevation_deg` above it. 0: the walk.
  double ring_step_deg = 0.0;
  double ring_distance = 0.8;
  double ring_elevation_deg = 30.0;
  /// writeTumFolder: poses written in metres times this (1000: millimetres). Depth PNGs hold
  /// 5000 units per metre, so a scale other than 1 needs write_depth = false.
  double unit_scale = 1.0;
  bool write_depth = true;  ///< false: no depth/ and no depth.txt (a photo collection)

  /// Throws InvalidArgument naming the bad value.
  void validate() const;
};

struct SyntheticFrame {
  double stamp = 0.0;     ///< [s], a whole number of microseconds (written exactly in TUM lists)
  core::CameraPose pose;  ///< camera-to-world, optical frame (z forward, x right, y down)
  cv::Mat colour;         ///< CV_8UC3, BGR (cv::imwrite stores it as an RGB PNG)
  cv::Mat depth;          ///< CV_16UC1, TUM units: 5000 per metre of z-depth, 0 = no surface
};

/// Progress callback: frames done, frames in total.
using SyntheticProgress = std::function<void(size_t, size_t)>;

class SyntheticSequence {
 public:
  /// Builds the scene and the camera path (cheap); frames are rendered on demand.
  explicit SyntheticSequence(const SyntheticSequenceConfig& config);

  const SyntheticSequenceConfig& config() const { return config_; }
  const SyntheticScene& scene() const { return scene_; }
  size_t size() const { return path_.size(); }
  /// Stamp and exact camera-to-world pose of every frame (the groundtruth.txt content).
  const std::vector<io::TumPoseEntry>& path() const { return path_; }

  /// Renders frame `index` (throws InvalidArgument when out of range).
  SyntheticFrame render(size_t index) const;

  /// Writes a TUM RGB-D folder: rgb/ and depth/ PNGs named by stamp, rgb.txt, depth.txt,
  /// groundtruth.txt, camera.yaml and SOURCE.md. The folder is created when missing; files of
  /// the same names are replaced, other files are left alone. Frames are rendered in parallel
  /// on OpenCV's threads (cv::setNumThreads); the files do not depend on the thread count, and
  /// `progress` is called from one thread at a time. Throws IoError.
  void writeTumFolder(const std::string& folder, const SyntheticProgress& progress = {}) const;

 private:
  SyntheticSequenceConfig config_;
  SyntheticScene scene_;
  std::vector<io::TumPoseEntry> path_;
};

/// The handheld-like loop: an ellipse around the room's middle walked at `config.speed`, slow
/// sways of position and view direction (mostly towards the walls and the objects standing
/// there, tilted down), and small fast jitter like a hand's. Stamps start_stamp + i / fps,
/// rounded to whole microseconds. Quaternions are unit length and have qw >= 0.
std::vector<io::TumPoseEntry> syntheticCameraPath(const SyntheticSequenceConfig& config);

/// The ring (or arc) of SyntheticSequenceConfig::ring_step_deg around `target`: view i at
/// azimuth i * ring_step_deg, z up. Stamps as the walk's.
std::vector<io::TumPoseEntry> syntheticRingPath(const SyntheticSequenceConfig& config,
                                                const Eigen::Vector3d& target);

}  // namespace view_selection::sim
