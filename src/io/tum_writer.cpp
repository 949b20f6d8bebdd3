// Writer side of the TUM RGB-D layout: groundtruth.txt, rgb.txt / depth.txt and the flat
// camera.yaml, in exactly the forms the reader in tum_dataset.cpp accepts.
#include "view_selection/core/exceptions.h"
#include "view_selection/io/tum_dataset.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

namespace view_selection::io {
namespace {

std::string inQuotes(const std::string& s) { return "'" + s + "'"; }

/// Shortest text that reads back as exactly the same double (std::from_chars in the reader).
std::string exact(double value) {
  char buffer[64];
  const auto [end, ec] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  if (ec != std::errc())
    throw core::IoError("cannot format a number");  // cannot happen with 64 chars
  return std::string(buffer, end);
}

std::string sixDecimals(double stamp) {
  std::ostringstream out;
  out.imbue(std::locale::classic());
  out << std::fixed << std::setprecision(6) << stamp;
  return out.str();
}

/// Comment lines, each prefixed with "# "; a multi-line comment gives several lines.
void writeComment(std::ostream& out, const std::string& comment) {
  if (comment.empty()) return;
  std::istringstream lines(comment);
  std::string line;
  while (std::getline(lines, line)) out << "# " << line << "\n";
}

/// Writes `content` to `path` in one go; throws IoError naming the file.
void writeFile(const std::string& path, const std::string& content) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw core::IoError("cannot open " + inQuotes(path) + " for writing");
  out << content;
  out.close();
  if (!out) throw core::IoError("error while writing " + inQuotes(path) + " (disk full?)");
}

}  // namespace

void writeTumTrajectory(const std::string& path, const std::vector<TumPoseEntry>& poses,
                        const std::string& comment) {
  std::ostringstream out;
  writeComment(out, comment);
  out << "# timestamp tx ty tz qx qy qz qw\n";
  std::set<double> stamps;
  for (size_t q = 0; q < poses.size(); ++q) {
    const TumPoseEntry& e = poses[q];
    if (!std::isfinite(e.stamp) || !e.pose.isValid()) {
      throw core::IoError("cannot write " + inQuotes(path) + ": pose " + std::to_string(q) +
                          " has a non-finite value or a quaternion far from unit length");
    }
    if (!stamps.insert(e.stamp).second) {
      throw core::IoError("cannot write " + inQuotes(path) + ": stamp " + exact(e.stamp) +
                          " appears twice (the reader rejects repeated stamps)");
    }
    const Eigen::Vector3d& t = e.pose.position;
    const Eigen::Quaterniond& r = e.pose.orientation;
    out << exact(e.stamp) << ' ' << exact(t.x()) << ' ' << exact(t.y()) << ' ' << exact(t.z())
        << ' ' << exact(r.x()) << ' ' << exact(r.y()) << ' ' << exact(r.z()) << ' ' << exact(r.w())
        << '\n';
  }
  writeFile(path, out.str());
}

void writeTumImageList(const std::string& path, const std::vector<TumImageEntry>& entries,
                       const std::string& comment) {
  std::ostringstream out;
  writeComment(out, comment);
  out << "# timestamp filename\n";
  std::set<std::string> stamps;
  for (size_t q = 0; q < entries.size(); ++q) {
    const TumImageEntry& e = entries[q];
    if (!std::isfinite(e.stamp)) {
      throw core::IoError("cannot write " + inQuotes(path) + ": entry " + std::to_string(q) +
                          " has a non-finite stamp");
    }
    if (e.path.empty() || std::any_of(e.path.begin(), e.path.end(),
                                      [](unsigned char c) { return std::isspace(c) != 0; })) {
      throw core::IoError("cannot write " + inQuotes(path) + ": image path " + inQuotes(e.path) +
                          " is empty or contains whitespace, which the list format cannot hold");
    }
    const std::string stamp = sixDecimals(e.stamp);
    if (!stamps.insert(stamp).second) {
      throw core::IoError("cannot write " + inQuotes(path) + ": stamp " + stamp +
                          " appears twice at 6 decimals (the reader rejects repeated stamps)");
    }
    out << stamp << ' ' << e.path << '\n';
  }
  writeFile(path, out.str());
}

void writeCameraYaml(const std::string& path, const core::PinholeIntrinsics& k) {
  if (!k.isValid() || !std::isfinite(k.cx) || !std::isfinite(k.cy)) {
    throw core::IoError("cannot write " + inQuotes(path) +
                        ": the intrinsics are invalid (focal lengths and size must be positive)");
  }
  std::ostringstream out;
  out << "# Pinhole intrinsics in pixels (view_selection camera.yaml)\n"
      << "fx: " << exact(k.fx) << "\n"
      << "fy: " << exact(k.fy) << "\n"
      << "cx: " << exact(k.cx) << "\n"
      << "cy: " << exact(k.cy) << "\n"
      << "width: " << k.width << "\n"
      << "height: " << k.height << "\n";
  writeFile(path, out.str());
}

}  // namespace view_selection::io
