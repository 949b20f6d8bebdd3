// Reader for folders in TUM RGB-D layout: rgb.txt, depth.txt (optional), groundtruth.txt and the
// images they name, associated by nearest stamp within a tolerance (like TUM's associate.py).
#pragma once

#include "view_selection/core/types.h"

#include <optional>
#include <string>
#include <vector>

namespace view_selection::io {

/// One "stamp path" line of rgb.txt / depth.txt.
struct TumImageEntry {
  double stamp = 0.0;
  std::string path;  ///< relative to the dataset folder, as written in the list
};

/// One "stamp tx ty tz qx qy qz qw" line of groundtruth.txt (camera-to-world).
struct TumPoseEntry {
  double stamp = 0.0;
  core::CameraPose pose;
};

/// Reads rgb.txt / depth.txt. Lines starting with '#' and blank lines are skipped; "\r\n" line
/// endings are fine. Any other line must be exactly "stamp path" with a finite stamp (so a path
/// cannot contain whitespace); a malformed line or a stamp repeated in the file throws IoError
/// naming the file and the 1-based line number. Entries are returned in file order.
std::vector<TumImageEntry> readTumImageList(const std::string& path);
/// Reads groundtruth.txt (same rules; a non-finite value or a quaternion whose norm is far from 1,
/// see CameraPose::isValid, is malformed). Quaternions are stored normalised.
std::vector<TumPoseEntry> readTumTrajectory(const std::string& path);
/// Writes groundtruth.txt format (8 columns, full double precision). Throws IoError.
void writeTumTrajectory(const std::string& path, const std::vector<TumPoseEntry>& poses,
                        const std::string& comment = "");
/// Writes rgb.txt / depth.txt format ("stamp path", stamps with 6 decimals). Throws IoError.
void writeTumImageList(const std::string& path, const std::vector<TumImageEntry>& entries,
                       const std::string& comment = "");

/// Intrinsics from a YAML file: flat keys fx, fy, cx, cy, width, height (this package's
/// camera.yaml), or a ROS camera_info calibration file (image_width, image_height,
/// camera_matrix/data). Throws IoError naming the file and what is missing.
core::PinholeIntrinsics loadCameraYaml(const std::string& path);
/// Writes the flat camera.yaml format. Throws IoError.
void writeCameraYaml(const std::string& path, const core::PinholeIntrinsics& intrinsics);
/// TUM's published colour intrinsics for freiburg1/2/3, chosen by a folder name containing
/// "freiburg1" / "fr1" etc.; empty when the name says none.
std::optional<core::PinholeIntrinsics> tumDefaultIntrinsics(const std::string& folder_name);

/// Greedy unique association of two stamp lists, as associate.py does: candidate pairs with
/// |a - b| < max_difference (strict), best first, each element used once. Ties in the difference
/// are broken as associate.py's tuple sort does: smaller first-list stamp, then smaller
/// second-list stamp (then smaller indices, for repeated stamps). Returns index pairs sorted by
/// the first list's index. Throws InvalidArgument for a negative or NaN max_difference.
std::vector<std::pair<size_t, size_t>> associateStamps(const std::vector<double>& a,
                                                       const std::vector<double>& b,
                                                       double max_difference);

struct TumFrame {
  double stamp = 0.0;      ///< rgb stamp [s]
  std::string rgb_path;    ///< relative to the dataset folder
  std::string depth_path;  ///< relative to the dataset folder; empty without depth
  double depth_stamp = 0.0;
  core::CameraPose pose;  ///< ground truth nearest to the rgb stamp (camera-to-world)
  double pose_stamp = 0.0;
};

struct TumDatasetOptions {
  double max_time_difference = 0.02;  ///< association tolerance [s] (associate.py's default)
};

struct TumDataset {
  std::string root;  ///< the folder, as given
  core::PinholeIntrinsics intrinsics;
  std::string intrinsics_source;                ///< "camera.yaml", or "TUM freiburg1 defaults", ...
  bool has_depth = false;                       ///< depth.txt present and associated
  double depth_metres_per_unit = 1.0 / 5000.0;  ///< TUM depth PNGs: 5000 units per metre
  std::string image_dir;         ///< folder COLMAP is given as --image_path, relative to root
  std::vector<TumFrame> frames;  ///< associated frames, ascending stamp
  size_t rgb_entries = 0;        ///< lines in rgb.txt
  /// rgb frames with no depth within the tolerance (after the unique rgb<->depth association).
  size_t dropped_without_depth = 0;
  /// rgb frames with depth (or without depth.txt) but no ground truth within the tolerance; a
  /// frame is counted once, so rgb_entries = frames + dropped_without_depth + dropped_without_pose.
  size_t dropped_without_pose = 0;

  /// Image name of a frame relative to image_dir (the name pairs.txt uses). image_dir is the
  /// longest directory (whole components) shared by every rgb path, "" when none. Throws
  /// InvalidArgument for a frame whose rgb_path is not inside image_dir.
  std::string imageName(const TumFrame& frame) const;
};

/// Loads and associates a TUM-layout folder. rgb<->depth (when depth.txt exists) by
/// associateStamps; each remaining rgb frame takes the ground-truth pose nearest to its stamp
/// within the tolerance (not unique: ground truth may be denser; a tie takes the earlier pose).
/// Intrinsics from camera.yaml, else tumDefaultIntrinsics(folder name). Throws IoError (missing
/// folder or files, malformed lines, no intrinsics, an associated image file missing) or
/// InvalidInput (no frame left after association), with one clear message; InvalidArgument for
/// a non-positive max_time_difference.
TumDataset loadTumDataset(const std::string& folder, const TumDatasetOptions& options = {});

}  // namespace view_selection::io
