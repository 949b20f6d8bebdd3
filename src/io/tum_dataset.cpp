// Reader side of the TUM RGB-D layout: the two list formats, camera YAML, association by stamp
// and the dataset loader. The writers live in tum_writer.cpp.
#include "view_selection/io/tum_dataset.h"

#include "view_selection/core/exceptions.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <limits>
#include <sstream>
#include <tuple>
#include <unordered_map>

namespace view_selection::io {
namespace {

namespace fs = std::filesystem;

std::string inQuotes(const std::string& s) { return "'" + s + "'"; }

std::string formatStamp(double stamp) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(6) << stamp;
  return out.str();
}

/// Throws IoError unless `path` names a readable regular file; returns the open stream.
std::ifstream openForReading(const std::string& path) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (!fs::exists(status))
    throw core::IoError("cannot read " + inQuotes(path) + ": file does not exist");
  if (fs::is_directory(status)) {
    throw core::IoError("cannot read " + inQuotes(path) + ": it is a folder, not a file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw core::IoError("cannot open " + inQuotes(path) + " for reading (permissions?)");
  return in;
}

/// Calls `handle(tokens, line_number)` for every line that is neither blank nor a '#' comment.
/// Tokens are split on ASCII whitespace, so "\r\n" line endings need no special case.
void forEachDataLine(const std::string& path,
                     const std::function<void(const std::vector<std::string>&, size_t)>& handle) {
  std::ifstream in = openForReading(path);
  std::string line;
  size_t line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    // A UTF-8 byte order mark (Windows editors) is not part of the first stamp.
    if (line_number == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);
    std::vector<std::string> tokens;
    std::istringstream fields(line);
    std::string token;
    while (fields >> token) tokens.push_back(token);
    if (tokens.empty() || tokens.front()[0] == '#') continue;
    handle(tokens, line_number);
  }
  if (in.bad()) {
    throw core::IoError("error while reading " + inQuotes(path) + " after line " +
                        std::to_string(line_number));
  }
}

std::string lineContext(const std::string& path, size_t line_number) {
  return inQuotes(path) + " line " + std::to_string(line_number) + ": ";
}

/// Parses a whole token as a finite double (locale-independent); throws IoError otherwise.
double parseFinite(const std::string& token, const std::string& what, const std::string& path,
                   size_t line_number) {
  const char* begin = token.data();
  const char* end = token.data() + token.size();
  if (begin != end && *begin == '+') ++begin;  // from_chars rejects an explicit plus sign
  double value = 0.0;
  const auto [ptr, ec] = std::from_chars(begin, end, value);
  if (ec == std::errc::result_out_of_range) {
    throw core::IoError(lineContext(path, line_number) + what + " " + inQuotes(token) +
                        " is out of the range of a double");
  }
  if (ec != std::errc() || ptr != end || begin == end) {
    throw core::IoError(lineContext(path, line_number) + what + " " + inQuotes(token) +
                        " is not a number");
  }
  if (!std::isfinite(value)) {
    throw core::IoError(lineContext(path, line_number) + what + " " + inQuotes(token) +
                        " is not finite");
  }
  return value;
}

/// Remembers the line of every stamp of one file; throws IoError on a repeated stamp.
class DuplicateStampCheck {
 public:
  explicit DuplicateStampCheck(const std::string& path) : path_(path) {}
  void add(double stamp, const std::string& token, size_t line_number) {
    const auto [it, inserted] = first_line_.emplace(stamp, line_number);
    if (!inserted) {
      throw core::IoError(lineContext(path_, line_number) + "duplicate stamp " + token +
                          " (already on line " + std::to_string(it->second) + ")");
    }
  }

 private:
  std::string path_;
  std::unordered_map<double, size_t> first_line_;
};

// ---------------------------------------------------------------------------------------------
// camera YAML

double yamlNumber(const YAML::Node& map, const std::string& key, const std::string& path,
                  const std::string& key_path) {
  const YAML::Node node = map[key];
  if (!node) throw core::IoError(inQuotes(path) + ": missing key " + inQuotes(key_path));
  if (!node.IsScalar()) {
    throw core::IoError(inQuotes(path) + ": key " + inQuotes(key_path) + " is not a number");
  }
  double value = 0.0;
  try {
    value = node.as<double>();
  } catch (const YAML::Exception&) {
    throw core::IoError(inQuotes(path) + ": key " + inQuotes(key_path) + " is not a number (" +
                        inQuotes(node.Scalar()) + ")");
  }
  if (!std::isfinite(value)) {
    throw core::IoError(inQuotes(path) + ": key " + inQuotes(key_path) + " is not finite (" +
                        inQuotes(node.Scalar()) + ")");
  }
  return value;
}

int yamlImageSize(const YAML::Node& map, const std::string& key, const std::string& path) {
  const double value = yamlNumber(map, key, path, key);
  if (value <= 0.0 || value != std::floor(value) ||
      value > static_cast<double>(std::numeric_limits<int>::max())) {
    throw core::IoError(inQuotes(path) + ": key " + inQuotes(key) + " = " + map[key].Scalar() +
                        " must be a positive whole number of pixels");
  }
  return static_cast<int>(value);
}

void requirePositiveFocal(double value, const std::string& key_path, const std::string& path) {
  if (value <= 0.0) {
    std::ostringstream msg;
    msg << inQuotes(path) << ": " << inQuotes(key_path) << " = " << value
        << " is not a valid focal length (must be positive, in pixels)";
    throw core::IoError(msg.str());
  }
}

core::PinholeIntrinsics rosCalibration(const YAML::Node& root, const std::string& path) {
  core::PinholeIntrinsics k;
  k.width = yamlImageSize(root, "image_width", path);
  k.height = yamlImageSize(root, "image_height", path);
  const YAML::Node matrix = root["camera_matrix"];
  if (!matrix.IsMap()) {
    throw core::IoError(inQuotes(path) +
                        ": key 'camera_matrix' must be a map with rows, cols and data");
  }
  for (const char* dim : {"rows", "cols"}) {
    if (!matrix[dim]) continue;  // optional; when given it must say 3
    const double n = yamlNumber(matrix, dim, path, std::string("camera_matrix/") + dim);
    if (n != 3.0) {
      throw core::IoError(inQuotes(path) + ": 'camera_matrix/" + dim + "' is " +
                          matrix[dim].Scalar() + ", expected 3");
    }
  }
  const YAML::Node data = matrix["data"];
  if (!data) throw core::IoError(inQuotes(path) + ": missing key 'camera_matrix/data'");
  if (!data.IsSequence() || data.size() != 9) {
    throw core::IoError(
        inQuotes(path) +
        ": 'camera_matrix/data' must be a list of 9 numbers [fx 0 cx 0 fy cy 0 0 1]");
  }
  double m[9];
  for (size_t i = 0; i < 9; ++i) {
    const std::string key_path = "camera_matrix/data[" + std::to_string(i) + "]";
    if (!data[i].IsScalar())
      throw core::IoError(inQuotes(path) + ": " + inQuotes(key_path) + " is not a number");
    try {
      m[i] = data[i].as<double>();
    } catch (const YAML::Exception&) {
      throw core::IoError(inQuotes(path) + ": " + inQuotes(key_path) + " is not a number (" +
                          inQuotes(data[i].Scalar()) + ")");
    }
    if (!std::isfinite(m[i])) {
      throw core::IoError(inQuotes(path) + ": " + inQuotes(key_path) + " is not finite");
    }
  }
  // A skewed or non-normalised matrix cannot be represented by PinholeIntrinsics.
  if (m[1] != 0.0 || m[3] != 0.0 || m[6] != 0.0 || m[7] != 0.0 || m[8] != 1.0) {
    throw core::IoError(inQuotes(path) +
                        ": 'camera_matrix/data' is not of the form [fx 0 cx 0 fy cy 0 0 1]");
  }
  requirePositiveFocal(m[0], "camera_matrix/data[0] (fx)", path);
  requirePositiveFocal(m[4], "camera_matrix/data[4] (fy)", path);
  k.fx = m[0];
  k.cx = m[2];
  k.fy = m[4];
  k.cy = m[5];
  return k;
}

// ---------------------------------------------------------------------------------------------
// TUM defaults

/// 1, 2 or 3 when the name says exactly one freiburg camera, 0 otherwise.
int freiburgCamera(const std::string& folder_name) {
  std::string name = folder_name;
  std::transform(name.begin(), name.end(), name.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  int found = 0;
  for (int camera = 1; camera <= 3; ++camera) {
    const std::string digit = std::to_string(camera);
    if (name.find("freiburg" + digit) != std::string::npos ||
        name.find("fr" + digit) != std::string::npos) {
      if (found != 0) return 0;  // two cameras named: ambiguous, let the user decide
      found = camera;
    }
  }
  return found;
}

std::string folderBaseName(const std::string& folder) {
  std::error_code ec;
  fs::path p = fs::absolute(fs::path(folder), ec);
  if (ec) p = fs::path(folder);
  p = p.lexically_normal();
  if (p.filename().empty()) p = p.parent_path();  // "a/b/" normalises to "a/b/"
  return p.filename().string();
}

// ---------------------------------------------------------------------------------------------
// association helpers

/// Index of the entry of `sorted_stamps` nearest to `stamp` with |difference| < max_difference,
/// the earlier stamp on a tie; -1 when none.
long nearestWithin(const std::vector<double>& sorted_stamps, double stamp, double max_difference) {
  const auto it = std::lower_bound(sorted_stamps.begin(), sorted_stamps.end(), stamp);
  long best = -1;
  double best_difference = max_difference;
  if (it != sorted_stamps.begin()) {
    const auto before = std::prev(it);
    const double d = std::abs(stamp - *before);
    if (d < best_difference) {
      best = before - sorted_stamps.begin();
      best_difference = d;
    }
  }
  if (it != sorted_stamps.end()) {
    const double d = std::abs(*it - stamp);
    if (d < best_difference) best = it - sorted_stamps.begin();  // strictly nearer only
  }
  return best;
}

std::string stampRange(const std::vector<double>& stamps) {
  if (stamps.empty()) return "none";
  const auto [lo, hi] = std::minmax_element(stamps.begin(), stamps.end());
  return formatStamp(*lo) + " .. " + formatStamp(*hi) + " s";
}

bool isRegularFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

/// Longest directory prefix shared by all paths, on whole path components; "" when none.
std::string commonDirectory(const std::vector<TumFrame>& frames) {
  auto directoryOf = [](const std::string& path) {
    const size_t slash = path.rfind('/');
    return slash == std::string::npos ? std::string() : path.substr(0, slash);
  };
  auto within = [](const std::string& dir, const std::string& prefix) {
    return dir == prefix ||
           (dir.size() > prefix.size() && dir.compare(0, prefix.size(), prefix) == 0 &&
            dir[prefix.size()] == '/');
  };
  if (frames.empty()) return "";
  std::string common = directoryOf(frames.front().rgb_path);
  for (const TumFrame& frame : frames) {
    const std::string dir = directoryOf(frame.rgb_path);
    while (!common.empty() && !within(dir, common)) common = directoryOf(common);
  }
  return common;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

std::vector<TumImageEntry> readTumImageList(const std::string& path) {
  std::vector<TumImageEntry> entries;
  DuplicateStampCheck duplicates(path);
  forEachDataLine(path, [&](const std::vector<std::string>& tokens, size_t line_number) {
    if (tokens.size() != 2) {
      throw core::IoError(lineContext(path, line_number) +
                          "expected 2 columns 'stamp path', found " +
                          std::to_string(tokens.size()) +
                          (tokens.size() < 2 ? " (the image path is missing)"
                                             : " (image paths must not contain whitespace)"));
    }
    TumImageEntry entry;
    entry.stamp = parseFinite(tokens[0], "stamp", path, line_number);
    entry.path = tokens[1];
    duplicates.add(entry.stamp, tokens[0], line_number);
    entries.push_back(std::move(entry));
  });
  return entries;
}

std::vector<TumPoseEntry> readTumTrajectory(const std::string& path) {
  static const char* const kColumns[8] = {"stamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"};
  std::vector<TumPoseEntry> poses;
  DuplicateStampCheck duplicates(path);
  forEachDataLine(path, [&](const std::vector<std::string>& tokens, size_t line_number) {
    if (tokens.size() != 8) {
      throw core::IoError(lineContext(path, line_number) +
                          "expected 8 columns 'stamp tx ty tz qx qy qz qw', found " +
                          std::to_string(tokens.size()));
    }
    double v[8];
    for (size_t i = 0; i < 8; ++i) v[i] = parseFinite(tokens[i], kColumns[i], path, line_number);
    TumPoseEntry entry;
    entry.stamp = v[0];
    entry.pose.position = Eigen::Vector3d(v[1], v[2], v[3]);
    entry.pose.orientation = Eigen::Quaterniond(v[7], v[4], v[5], v[6]);  // w, x, y, z
    if (!entry.pose.isValid()) {
      std::ostringstream msg;
      msg << lineContext(path, line_number) << "quaternion (qx qy qz qw) = (" << tokens[4] << " "
          << tokens[5] << " " << tokens[6] << " " << tokens[7] << ") has norm "
          << entry.pose.orientation.norm() << "; expected a unit quaternion";
      throw core::IoError(msg.str());
    }
    entry.pose.orientation.normalize();
    duplicates.add(entry.stamp, tokens[0], line_number);
    poses.push_back(entry);
  });
  return poses;
}

core::PinholeIntrinsics loadCameraYaml(const std::string& path) {
  openForReading(path);  // clear message for a missing file or a folder
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& e) {
    throw core::IoError(inQuotes(path) + " is not valid YAML: " + e.what());
  }
  if (!root.IsMap()) {
    throw core::IoError(inQuotes(path) +
                        " is not a map of keys; expected fx, fy, cx, cy, width, height (or a ROS "
                        "camera calibration file)");
  }
  try {
    if (root["camera_matrix"]) return rosCalibration(root, path);
    core::PinholeIntrinsics k;
    k.fx = yamlNumber(root, "fx", path, "fx");
    k.fy = yamlNumber(root, "fy", path, "fy");
    k.cx = yamlNumber(root, "cx", path, "cx");
    k.cy = yamlNumber(root, "cy", path, "cy");
    k.width = yamlImageSize(root, "width", path);
    k.height = yamlImageSize(root, "height", path);
    requirePositiveFocal(k.fx, "fx", path);
    requirePositiveFocal(k.fy, "fy", path);
    return k;
  } catch (const YAML::Exception& e) {  // e.g. indexing into a scalar
    throw core::IoError(inQuotes(path) + ": unexpected structure: " + e.what());
  }
}

std::optional<core::PinholeIntrinsics> tumDefaultIntrinsics(const std::string& folder_name) {
  // TUM RGB-D's published colour intrinsics (their ROS default calibration), 640x480.
  auto make = [](double fx, double fy, double cx, double cy) {
    core::PinholeIntrinsics k;
    k.fx = fx;
    k.fy = fy;
    k.cx = cx;
    k.cy = cy;
    k.width = 640;
    k.height = 480;
    return k;
  };
  switch (freiburgCamera(folder_name)) {
    case 1:
      return make(517.3, 516.5, 318.6, 255.3);
    case 2:
      return make(520.9, 521.0, 325.1, 249.7);
    case 3:
      return make(535.4, 539.2, 320.1, 247.6);
    default:
      return std::nullopt;
  }
}

std::vector<std::pair<size_t, size_t>> associateStamps(const std::vector<double>& a,
                                                       const std::vector<double>& b,
                                                       double max_difference) {
  if (!(max_difference >= 0.0)) {
    throw core::InvalidArgument("associateStamps: max_difference must be >= 0, got " +
                                std::to_string(max_difference));
  }
  // b's indices by stamp; NaN stamps can never match and would break the ordering.
  std::vector<size_t> b_order;
  b_order.reserve(b.size());
  for (size_t j = 0; j < b.size(); ++j) {
    if (!std::isnan(b[j])) b_order.push_back(j);
  }
  std::stable_sort(b_order.begin(), b_order.end(), [&](size_t x, size_t y) { return b[x] < b[y]; });

  // Candidates (difference, a stamp, b stamp, i, j): associate.py sorts (difference, a, b)
  // tuples, so ties go to the smaller first stamp, then the smaller second stamp; the indices
  // only order exact duplicates.
  using Candidate = std::tuple<double, double, double, size_t, size_t>;
  std::vector<Candidate> candidates;
  for (size_t i = 0; i < a.size(); ++i) {
    if (std::isnan(a[i])) continue;
    const auto start = std::lower_bound(b_order.begin(), b_order.end(), a[i],
                                        [&](size_t j, double s) { return b[j] < s; });
    // |a - b| grows monotonically (also after rounding) moving away from a, so walk outwards.
    for (auto it = start; it != b_order.end(); ++it) {
      const double d = std::abs(a[i] - b[*it]);
      if (!(d < max_difference)) break;
      candidates.emplace_back(d, a[i], b[*it], i, *it);
    }
    for (auto it = start; it != b_order.begin();) {
      --it;
      const double d = std::abs(a[i] - b[*it]);
      if (!(d < max_difference)) break;
      candidates.emplace_back(d, a[i], b[*it], i, *it);
    }
  }
  std::sort(candidates.begin(), candidates.end());

  std::vector<bool> a_used(a.size(), false);
  std::vector<bool> b_used(b.size(), false);
  std::vector<std::pair<size_t, size_t>> matches;
  for (const Candidate& c : candidates) {
    const size_t i = std::get<3>(c);
    const size_t j = std::get<4>(c);
    if (a_used[i] || b_used[j]) continue;
    a_used[i] = true;
    b_used[j] = true;
    matches.emplace_back(i, j);
  }
  std::sort(matches.begin(), matches.end());
  return matches;
}

std::string TumDataset::imageName(const TumFrame& frame) const {
  if (image_dir.empty()) return frame.rgb_path;
  if (frame.rgb_path.size() > image_dir.size() + 1 &&
      frame.rgb_path.compare(0, image_dir.size(), image_dir) == 0 &&
      frame.rgb_path[image_dir.size()] == '/') {
    return frame.rgb_path.substr(image_dir.size() + 1);
  }
  throw core::InvalidArgument("image " + inQuotes(frame.rgb_path) +
                              " is not inside the image folder " + inQuotes(image_dir) +
                              " of dataset " + inQuotes(root));
}

namespace {

/// Throws IoError unless `folder` is a folder with rgb.txt and groundtruth.txt.
void checkDatasetFolder(const std::string& folder) {
  const fs::path root(folder);
  std::error_code ec;
  const fs::file_status status = fs::status(root, ec);
  if (!fs::exists(status))
    throw core::IoError("dataset folder " + inQuotes(folder) + " does not exist");
  if (!fs::is_directory(status)) {
    throw core::IoError("dataset folder " + inQuotes(folder) + " is not a folder");
  }
  if (!fs::exists(root / "rgb.txt", ec)) {
    throw core::IoError("dataset folder " + inQuotes(folder) +
                        " has no rgb.txt (the list of colour images, one 'stamp path' per line)");
  }
  if (!fs::exists(root / "groundtruth.txt", ec)) {
    throw core::IoError(
        "dataset folder " + inQuotes(folder) +
        " has no groundtruth.txt: the view selection needs the camera pose of every "
        "frame (one 'stamp tx ty tz qx qy qz qw' line per pose, camera-to-world)");
  }
}

/// camera.yaml, else TUM's published intrinsics for the camera the folder's name says.
void loadIntrinsics(const std::string& folder, TumDataset& dataset) {
  std::error_code ec;
  const fs::path camera_file = fs::path(folder) / "camera.yaml";
  if (fs::exists(camera_file, ec)) {
    dataset.intrinsics = loadCameraYaml(camera_file.string());
    dataset.intrinsics_source = "camera.yaml";
    return;
  }
  const std::string name = folderBaseName(folder);
  const std::optional<core::PinholeIntrinsics> defaults = tumDefaultIntrinsics(name);
  if (!defaults) {
    throw core::IoError("dataset folder " + inQuotes(folder) +
                        " has no camera.yaml and its name does not say which TUM camera "
                        "(freiburg1/2/3) took it; add a camera.yaml with the keys fx, fy, cx, cy, "
                        "width, height (pixels)");
  }
  dataset.intrinsics = *defaults;
  dataset.intrinsics_source = "TUM freiburg" + std::to_string(freiburgCamera(name)) + " defaults";
}

std::vector<double> stampsOf(const std::vector<TumImageEntry>& entries) {
  std::vector<double> stamps;
  for (const auto& e : entries) stamps.push_back(e.stamp);
  return stamps;
}

/// rgb <-> depth by associate.py's unique greedy association, then each rgb frame with depth to
/// the nearest ground-truth pose (not unique: ground truth is often denser than the images).
void associateFrames(const std::string& folder, const std::vector<TumImageEntry>& rgb,
                     const std::vector<TumImageEntry>& depth, const std::vector<TumPoseEntry>& gt,
                     double max_difference, TumDataset& dataset) {
  std::vector<long> depth_of(rgb.size(), -1);
  if (dataset.has_depth) {
    for (const auto& [i, j] : associateStamps(stampsOf(rgb), stampsOf(depth), max_difference))
      depth_of[i] = static_cast<long>(j);
  }
  std::vector<size_t> gt_order(gt.size());
  for (size_t k = 0; k < gt.size(); ++k) gt_order[k] = k;
  std::sort(gt_order.begin(), gt_order.end(),
            [&](size_t x, size_t y) { return gt[x].stamp < gt[y].stamp; });
  std::vector<double> gt_stamps;
  for (size_t k : gt_order) gt_stamps.push_back(gt[k].stamp);

  for (size_t i = 0; i < rgb.size(); ++i) {
    if (dataset.has_depth && depth_of[i] < 0) {
      ++dataset.dropped_without_depth;
      continue;
    }
    const long nearest = nearestWithin(gt_stamps, rgb[i].stamp, max_difference);
    if (nearest < 0) {
      ++dataset.dropped_without_pose;
      continue;
    }
    const TumPoseEntry& pose = gt[gt_order[static_cast<size_t>(nearest)]];
    TumFrame frame;
    frame.stamp = rgb[i].stamp;
    frame.rgb_path = rgb[i].path;
    if (dataset.has_depth) {
      frame.depth_path = depth[static_cast<size_t>(depth_of[i])].path;
      frame.depth_stamp = depth[static_cast<size_t>(depth_of[i])].stamp;
    }
    frame.pose = pose.pose;
    frame.pose_stamp = pose.stamp;
    dataset.frames.push_back(std::move(frame));
  }

  if (dataset.frames.empty()) {
    std::ostringstream msg;
    msg << "dataset " << inQuotes(folder) << ": no frame left after association within "
        << max_difference << " s: of " << rgb.size() << " rgb images, ";
    if (dataset.has_depth) msg << dataset.dropped_without_depth << " have no depth image and ";
    msg << dataset.dropped_without_pose << " have no ground-truth pose that close in time (rgb "
        << stampRange(stampsOf(rgb));
    if (dataset.has_depth) msg << ", depth " << stampRange(stampsOf(depth));
    msg << ", ground truth " << stampRange(gt_stamps) << ")";
    throw core::InvalidInput(msg.str());
  }
  std::sort(dataset.frames.begin(), dataset.frames.end(),
            [](const TumFrame& x, const TumFrame& y) { return x.stamp < y.stamp; });
}

/// Throws IoError when an associated image is missing or its name cannot go into pairs.txt.
void checkImages(const std::string& folder, const TumDataset& dataset) {
  const fs::path root(folder);
  size_t missing = 0;
  size_t checked = 0;
  std::string first_missing;
  auto check = [&](const std::string& relative) {
    ++checked;
    if (isRegularFile(root / relative)) return;
    if (missing++ == 0) first_missing = (root / relative).string();
  };
  for (const TumFrame& frame : dataset.frames) {
    check(frame.rgb_path);
    if (dataset.has_depth) check(frame.depth_path);
  }
  if (missing > 0) {
    throw core::IoError("dataset " + inQuotes(folder) + ": " + std::to_string(missing) +
                        " of the " + std::to_string(checked) +
                        " associated image files do not exist; the first is " +
                        inQuotes(first_missing));
  }
  for (const TumFrame& frame : dataset.frames) {
    const std::string name = dataset.imageName(frame);
    // COLMAP's pairs.txt separates names by spaces.
    if (std::any_of(name.begin(), name.end(),
                    [](unsigned char c) { return std::isspace(c) != 0; })) {
      throw core::IoError("dataset " + inQuotes(folder) + ": image name " + inQuotes(name) +
                          " contains whitespace, which COLMAP's pairs.txt cannot hold; rename it");
    }
  }
}

}  // namespace

TumDataset loadTumDataset(const std::string& folder, const TumDatasetOptions& options) {
  if (!(options.max_time_difference > 0.0) || !std::isfinite(options.max_time_difference)) {
    throw core::InvalidArgument("max_time_difference must be positive and finite, got " +
                                std::to_string(options.max_time_difference));
  }
  checkDatasetFolder(folder);
  const fs::path root(folder);
  std::error_code ec;
  TumDataset dataset;
  dataset.root = folder;
  dataset.has_depth = fs::exists(root / "depth.txt", ec);

  const std::vector<TumImageEntry> rgb = readTumImageList((root / "rgb.txt").string());
  const std::vector<TumPoseEntry> gt = readTumTrajectory((root / "groundtruth.txt").string());
  std::vector<TumImageEntry> depth;
  if (dataset.has_depth) depth = readTumImageList((root / "depth.txt").string());
  dataset.rgb_entries = rgb.size();
  loadIntrinsics(folder, dataset);

  if (rgb.empty()) {
    throw core::InvalidInput("dataset " + inQuotes(folder) +
                             ": rgb.txt lists no images, no frame left");
  }
  if (gt.empty()) {
    throw core::InvalidInput("dataset " + inQuotes(folder) +
                             ": groundtruth.txt lists no poses, no frame left");
  }
  if (dataset.has_depth && depth.empty()) {
    throw core::InvalidInput(
        "dataset " + inQuotes(folder) +
        ": depth.txt lists no depth images, no frame left (remove depth.txt to "
        "load the colour images alone)");
  }
  associateFrames(folder, rgb, depth, gt, options.max_time_difference, dataset);
  dataset.image_dir = commonDirectory(dataset.frames);
  checkImages(folder, dataset);
  return dataset;
}

}  // namespace view_selection::io
