// Writing the synthetic sequence as a TUM RGB-D folder that loadTumDataset reads back exactly.
#include "view_selection/core/exceptions.h"
#include "view_selection/sim/synthetic_sequence.h"

#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include <filesystem>
#include <fstream>
#include <iomanip>
#include <mutex>
#include <sstream>

namespace view_selection::sim {
namespace {

namespace fs = std::filesystem;

std::string sixDecimals(double stamp) {
  std::ostringstream out;
  out.imbue(std::locale::classic());
  out << std::fixed << std::setprecision(6) << stamp;
  return out.str();
}

void createFolder(const fs::path& folder) {
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec || !fs::is_directory(folder)) {
    throw core::IoError("cannot create folder '" + folder.string() + "'" +
                        (ec ? ": " + ec.message() : std::string(": a file of that name exists")));
  }
}

void writePng(const fs::path& path, const cv::Mat& image) {
  // A fixed compression level: the files must not depend on OpenCV's default.
  const std::vector<int> params{cv::IMWRITE_PNG_COMPRESSION, 1};
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), image, params);
  } catch (const cv::Exception& e) {
    throw core::IoError("cannot write '" + path.string() + "': " + e.what());
  }
  if (!ok) throw core::IoError("cannot write '" + path.string() + "'");
}

std::string describe(const SyntheticSequence& sequence) {
  const SyntheticSequenceConfig& c = sequence.config();
  const core::PinholeIntrinsics& k = c.intrinsics;
  std::ostringstream s;
  s.imbue(std::locale::classic());
  s << "# Synthetic sequence (view_selection generate_sequence)\n\n"
    << "This folder is SYNTHETIC: rendered by view_selection's built-in generator, not recorded\n"
    << "with a camera. Same seed and options give byte-identical files.\n\n"
    << "- seed " << c.seed << ", " << sequence.size() << " frames at " << c.fps << " Hz, "
    << k.width << "x" << k.height << ", fx " << k.fx << " fy " << k.fy << " cx " << k.cx << " cy "
    << k.cy << "\n"
    << (c.ring_step_deg > 0.0
            ? "- a ring of views " + std::to_string(c.ring_step_deg) +
                  " deg apart around the box on the table, " + std::to_string(c.ring_distance) +
                  " m from its centre, " + std::to_string(c.ring_elevation_deg) +
                  " deg above it" + (c.write_depth ? "" : ", no depth (a photo collection)") +
                  ", positions in metres x " + std::to_string(c.unit_scale) + "\n"
            : std::string())
    << "- walking speed " << c.speed << " m/s, colour noise sigma " << c.noise_sigma
    << " grey levels, depth range " << c.max_range << " m\n"
    << "- scene: a " << c.scene.room_size.x() << " x " << c.scene.room_size.y() << " x "
    << c.scene.room_size.z() << " m room (floor at z = 0, z up) with "
    << sequence.scene().boxes().size() - 1 << " boxes inside, procedurally textured\n\n"
    << "Layout (TUM RGB-D): rgb/*.png colour (8-bit RGB), depth/*.png depth (16-bit, 5000 units\n"
    << "per metre of z-depth, 0 = no surface within range), rgb.txt and depth.txt ('stamp path'),\n"
    << "groundtruth.txt ('stamp tx ty tz qx qy qz qw': exact camera-to-world pose of the optical\n"
    << "frame, z forward, x right, y down; world z up), camera.yaml (pinhole intrinsics in\n"
    << "pixels). Colour and depth share stamps and poses exactly; there is no lens distortion\n"
    << "and no motion blur.\n";
  return s.str();
}

}  // namespace

void SyntheticSequence::writeTumFolder(const std::string& folder,
                                       const SyntheticProgress& progress) const {
  const fs::path root(folder);
  createFolder(root / "rgb");
  if (config_.write_depth) createFolder(root / "depth");
  // Lists of an earlier sequence go first, so a run cut short cannot leave them pointing at a
  // mix of old and new images.
  for (const char* list : {"rgb.txt", "depth.txt", "groundtruth.txt"}) {
    std::error_code ec;
    fs::remove(root / list, ec);
    if (ec) throw core::IoError("cannot replace '" + (root / list).string() + "': " + ec.message());
  }
  // Frames are independent (the noise is a hash of the pixel, not a stream), so they are
  // rendered and written in parallel on OpenCV's threads (cv::setNumThreads; 1 for one core)
  // and the files are the same whatever the thread count.
  const size_t n = size();
  std::vector<io::TumImageEntry> rgb(n), depth(n);
  std::mutex mutex;
  std::string error;
  size_t done = 0;
  cv::parallel_for_(
      cv::Range(0, static_cast<int>(n)),
      [&](const cv::Range& range) {
        for (int q = range.start; q < range.end; ++q) {
          const size_t i = static_cast<size_t>(q);
          {
            const std::lock_guard<std::mutex> lock(mutex);
            if (!error.empty()) return;  // another frame failed: stop early
          }
          try {
            const SyntheticFrame frame = render(i);
            const std::string name = sixDecimals(frame.stamp) + ".png";
            writePng(root / "rgb" / name, frame.colour);
            if (config_.write_depth) writePng(root / "depth" / name, frame.depth);
            rgb[i] = {frame.stamp, "rgb/" + name};
            depth[i] = {frame.stamp, "depth/" + name};
          } catch (const std::exception& e) {  // nothing may escape a worker thread
            const std::lock_guard<std::mutex> lock(mutex);
            if (error.empty()) error = e.what();
            return;
          }
          const std::lock_guard<std::mutex> lock(mutex);
          ++done;
          if (progress) progress(done, n);
        }
      },
      static_cast<double>(n));
  {
    // The frames' names come back through `mutex` (each worker takes it after its frame), not
    // only through the loop's end: ThreadSanitizer does not see how OpenCV's TBB back end joins.
    const std::lock_guard<std::mutex> lock(mutex);
    if (!error.empty()) throw core::IoError(error);
  }

  // The lists last: a folder cut short by an error or a kill has no rgb.txt and reads as such.
  std::ofstream source(root / "SOURCE.md", std::ios::binary | std::ios::trunc);
  source << describe(*this);
  source.close();
  if (!source) throw core::IoError("cannot write '" + (root / "SOURCE.md").string() + "'");
  io::writeCameraYaml((root / "camera.yaml").string(), config_.intrinsics);
  const std::string comment = "synthetic sequence, seed " + std::to_string(config_.seed);
  std::vector<io::TumPoseEntry> poses = path_;
  for (io::TumPoseEntry& e : poses) e.pose.position *= config_.unit_scale;
  io::writeTumTrajectory((root / "groundtruth.txt").string(), poses,
                         comment + "\nexact camera-to-world poses of the optical frame" +
                             (config_.unit_scale != 1.0
                                  ? ", positions in metres x " + std::to_string(config_.unit_scale)
                                  : std::string()));
  if (config_.write_depth)
    io::writeTumImageList((root / "depth.txt").string(), depth, comment + "\ndepth images");
  io::writeTumImageList((root / "rgb.txt").string(), rgb, comment + "\ncolour images");
}

}  // namespace view_selection::sim
