#include "view_selection/sim/corridor_walk.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/atomic_file.h"
#include "view_selection/io/tum_dataset.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
#include <filesystem>
#include <random>
#include <sstream>
#include <vector>

namespace view_selection::sim {

namespace fs = std::filesystem;

CorridorWalkConfig::CorridorWalkConfig() {
  intrinsics.fx = intrinsics.fy = 525.0;
  intrinsics.cx = 319.5;
  intrinsics.cy = 239.5;
  intrinsics.width = 640;
  intrinsics.height = 480;
}

void CorridorWalkConfig::validate() const {
  auto need = [](bool ok, const std::string& what) {
    if (!ok) throw core::InvalidArgument("corridor walk: " + what);
  };
  need(frames >= 1, "frames must be at least 1");
  need(intrinsics.isValid(), "intrinsics are unusable");
  need(spacing > 0.0 && std::isfinite(spacing), "spacing must be positive");
  need(width > 0.5 && height > 0.5, "the corridor must be at least 0.5 m wide and high");
  need(max_range > 0.0, "max_range must be positive");
  need(points >= 1 && points <= 100000, "points must be 1..100000");
  need(period > 0.0, "period must be positive");
}

io::PointsRecord corridorKeyframe(const CorridorWalkConfig& c, int index) {
  // One generator per keyframe: (seed, index) alone decide it.
  std::seed_seq seq{static_cast<uint32_t>(c.seed), static_cast<uint32_t>(c.seed >> 32),
                    static_cast<uint32_t>(index), 0x5ca1e12u};
  std::mt19937_64 rng(seq);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double s = static_cast<double>(index);
  // The walker drifts between the walls and bobs a little; the gaze swings from one wall to the
  // other over about 40 keyframes and tilts slightly, as a handheld camera does.
  const double half_w = 0.5 * c.width, half_h = 0.5 * c.height;
  const Eigen::Vector3d eye(0.4 * half_w * std::sin(0.047 * s + 0.3),
                            0.05 * half_h * std::sin(0.29 * s), c.spacing * s);
  const double yaw = 0.75 * std::sin(0.16 * s) + 0.1 * std::sin(0.023 * s);
  const double pitch = 0.12 * std::sin(0.07 * s + 1.0);
  const Eigen::Matrix3d r =
      (Eigen::AngleAxisd(yaw, -Eigen::Vector3d::UnitY()) *  // y is down: -y turns left to right
       Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  io::PointsRecord record;
  record.stamp = c.start_stamp + c.period * s;
  record.stamp = std::round(record.stamp * 1e6) / 1e6;  // whole microseconds, as TUM lists
  record.pose.position = eye;
  record.pose.orientation = Eigen::Quaterniond(r);
  std::vector<Eigen::Vector3d> points;
  points.reserve(static_cast<size_t>(c.points));
  // Random pixels; a ray that reaches no surface within max_range (down the corridor) is drawn
  // again, up to a bound, so a keyframe looking along the corridor still gets its points.
  for (int tries = 0; static_cast<int>(points.size()) < c.points && tries < 20 * c.points; ++tries) {
    const Eigen::Vector2d px(uni(rng) * c.intrinsics.width, uni(rng) * c.intrinsics.height);
    const Eigen::Vector3d ray = r * c.intrinsics.backProject(px);
    double t = std::numeric_limits<double>::infinity();
    for (int axis = 0; axis < 2; ++axis) {
      const double half = axis == 0 ? half_w : half_h;
      if (std::abs(ray[axis]) > 1e-12)
        t = std::min(t, ((ray[axis] > 0.0 ? half : -half) - eye[axis]) / ray[axis]);
    }
    if (!(t > 0.0) || t * ray.norm() > c.max_range) continue;
    points.push_back(eye + t * ray);
  }
  record.points.resize(3, static_cast<Eigen::Index>(points.size()));
  for (size_t q = 0; q < points.size(); ++q) record.points.col(static_cast<Eigen::Index>(q)) = points[q];
  return record;
}

void writeCorridorWalk(const std::string& folder, const CorridorWalkConfig& c,
                       const std::function<void(size_t, size_t)>& progress) {
  c.validate();
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) throw core::IoError("cannot create folder '" + folder + "': " + ec.message());
  const fs::path root(folder);
  const auto total = static_cast<size_t>(c.frames);
  std::vector<io::TumPoseEntry> poses;
  poses.reserve(total);
  io::writeAtomically((root / "points.bin").string(), [&](const std::string& tmp) {
    io::PointsFileWriter writer(tmp, c.intrinsics, total);
    for (size_t i = 0; i < total; ++i) {
      const io::PointsRecord r = corridorKeyframe(c, static_cast<int>(i));
      writer.write(r);
      poses.push_back({r.stamp, r.pose});
      if (progress && ((i + 1) % 1000 == 0 || i + 1 == total)) progress(i + 1, total);
    }
    writer.close();
  });
  io::writeTumTrajectory((root / "groundtruth.txt").string(), poses,
                         "corridor walk (generate_sequence --points-only): exact poses");
  io::writeCameraYaml((root / "camera.yaml").string(), c.intrinsics);
  std::ostringstream about;
  about << "# Synthetic corridor walk, points only\n\n"
        << "Written by `generate_sequence --points-only` (view_selection): " << c.frames
        << " keyframes, one every " << c.spacing << " m down a " << c.width << " x " << c.height
        << " m corridor, " << c.points << " sample points each (random pixels ray-cast onto the "
        << "walls, floor and ceiling within " << c.max_range << " m), seed " << c.seed
        << ". No images.\n\n"
        << "points.bin holds the poses and points (format in include/view_selection/io/"
        << "points_file.h); groundtruth.txt the same poses in TUM's format; camera.yaml the "
        << "intrinsics. `select_views --dataset` reads the folder.\n";
  io::writeFileContents((root / "SOURCE.md").string(), about.str());
}

}  // namespace view_selection::sim
