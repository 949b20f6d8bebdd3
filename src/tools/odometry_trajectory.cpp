// odometry_trajectory: the odometry stand-in (OpenCV's RGB-D odometry, as the rgbd_odometry node
// runs it) over a TUM RGB-D folder, offline: its drifting trajectory, and a copy of the folder
// whose groundtruth.txt is that trajectory, for select_views and colmap_from_selection.
#include "command_line.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/eval/trajectory_alignment.h"
#include "view_selection/io/tum_dataset.h"
#include "view_selection/odometry/rgbd_odometry.h"

#include <opencv2/imgcodecs.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>

namespace fs = std::filesystem;
using namespace view_selection;
using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;

namespace {

const char* kUsage = R"(usage: odometry_trajectory --dataset DIR --out FILE [options]

Runs the odometry stand-in (OpenCV's RGB-D odometry, the rgbd_odometry node's tracker at its
defaults) over a TUM RGB-D folder with depth, frame by frame, and writes its trajectory (TUM
format, camera-to-odom of the optical frame; frames it lost have no line). This is odometry: it
drifts and it does not close loops. When the folder has ground truth, prints the drift: the ATE
after a similarity alignment, and the end point's error as a share of the distance travelled.

  --dataset DIR      TUM RGB-D folder with depth.txt
  --out FILE         the trajectory (TUM groundtruth.txt format)
  --out-dataset DIR  also a copy of DIR (files linked) whose groundtruth.txt is the trajectory,
                     expressed in the ground truth's frame at the first frame (the exact poses
                     stay in groundtruth_exact.txt): select_views and colmap_from_selection
                     run on it as on SLAM poses
  --reference R      frame (default) or keyframe: the odometry's reference (the node's ~reference)
  --method M         rgbd (default), icp or rgbd_icp
  --max-width W      track on images made smaller by a whole factor until at most W wide (the
                     node's ~max_width, default 320; 0: full size)
  --every N          only every Nth frame (a front end that keeps up with 1 in N)
  --quiet            no summary
  --help             this text
)";

int run(int argc, char** argv) {
  const CommandLine cli(argc, argv, {"dataset", "out", "out-dataset", "reference", "method", "max-width", "every"}, {"quiet", "help"});
  if (cli.flag("help")) {
    std::cout << kUsage;
    return 0;
  }
  if (!cli.has("dataset") || !cli.has("out")) throw UsageError("--dataset and --out are required (see --help)");
  const io::TumDataset data = io::loadTumDataset(*cli.text("dataset"));
  if (!data.has_depth) throw core::InvalidInput(data.root + " has no depth: the RGB-D odometry needs it");
  odometry::OdometryConfig config;
  config.reference = cli.choice("reference", config.reference, {"keyframe", "frame"});
  config.method = cli.choice("method", config.method, {"rgbd", "icp", "rgbd_icp"});
  config.max_width = static_cast<int>(cli.integer("max-width", config.max_width, 0, 100000));
  const long every = cli.integer("every", 1, 1, 1000);
  odometry::RgbdOdometryTracker tracker(config);
  std::vector<io::TumPoseEntry> out;
  Eigen::Matrix3Xd est(3, static_cast<long>(data.frames.size())), gt(3, static_cast<long>(data.frames.size()));
  long matched = 0;
  double seconds = 0.0, travelled = 0.0;
  // The trajectory starts at the first frame's ground-truth pose, as a SLAM system started there
  // would report it (the ATE aligns anyway; a shared frame makes the files comparable).
  const Eigen::Isometry3d origin = [&] {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = data.frames.front().pose.rotation();
    t.translation() = data.frames.front().pose.position;
    return t;
  }();
  for (size_t q = 0; q < data.frames.size(); ++q) {
    const io::TumFrame& f = data.frames[q];
    if (q % static_cast<size_t>(every) != 0) {
      if (q > 0) travelled += (f.pose.position - data.frames[q - 1].pose.position).norm();
      continue;
    }
    const cv::Mat image = cv::imread((fs::path(data.root) / f.rgb_path).string(), cv::IMREAD_COLOR);
    const cv::Mat raw = cv::imread((fs::path(data.root) / f.depth_path).string(), cv::IMREAD_ANYDEPTH);
    if (image.empty() || raw.empty()) throw core::IoError("cannot read frame " + f.rgb_path + " / " + f.depth_path);
    cv::Mat depth;
    raw.convertTo(depth, CV_32F, raw.type() == CV_32F ? 1.0 : data.depth_metres_per_unit);
    const auto start = std::chrono::steady_clock::now();
    const odometry::OdometryResult r = tracker.track(f.stamp, image, depth, data.intrinsics);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (q > 0) travelled += (f.pose.position - data.frames[q - 1].pose.position).norm();
    if (r.status == odometry::OdometryResult::Status::kLost) {
      if (!cli.flag("quiet")) std::fprintf(stderr, "frame %.6f lost: %s\n", f.stamp, r.reason.c_str());
      continue;
    }
    const Eigen::Isometry3d pose = origin * r.pose;
    io::TumPoseEntry e;
    e.stamp = f.stamp;
    e.pose.position = pose.translation();
    e.pose.orientation = Eigen::Quaterniond(pose.linear()).normalized();
    out.push_back(e);
    est.col(matched) = e.pose.position;
    gt.col(matched++) = f.pose.position;
  }
  io::writeTumTrajectory(*cli.text("out"), out,
                         "odometry stand-in (OpenCV RGB-D odometry, " + config.method + ", reference " +
                             config.reference + ") on " + data.root);
  if (cli.has("out-dataset")) {
    const fs::path dst(*cli.text("out-dataset")), src = fs::absolute(data.root);
    fs::create_directories(dst);
    for (const auto& entry : fs::directory_iterator(src)) {
      const std::string name = entry.path().filename().string();
      if (name == "groundtruth.txt" || fs::exists(fs::symlink_status(dst / name))) continue;
      fs::create_symlink(entry.path(), dst / name);
    }
    fs::copy_file(src / "groundtruth.txt", dst / "groundtruth_exact.txt", fs::copy_options::overwrite_existing);
    io::writeTumTrajectory((dst / "groundtruth.txt").string(), out, "odometry stand-in poses");
  }
  if (!cli.flag("quiet")) {
    const odometry::OdometryCounts& c = tracker.counts();
    std::printf("odometry: %zu frames, %llu tracked, %llu lost, %llu restarts, %llu keyframes, %.1f ms a frame\n",
                data.frames.size(), static_cast<unsigned long long>(c.tracked),
                static_cast<unsigned long long>(c.lost), static_cast<unsigned long long>(c.restarts),
                static_cast<unsigned long long>(c.keyframes), 1000.0 * seconds / static_cast<double>(data.frames.size()));
    if (matched >= 3) {
      const eval::TrajectoryError e =
          eval::absoluteTrajectoryError(est.leftCols(matched), gt.leftCols(matched));
      const double end = (est.col(matched - 1) - gt.col(matched - 1)).norm();
      std::printf("drift: ATE %.4f (Sim(3)-aligned), end point %.4f = %.2f%% of %.3f travelled\n", e.rmse, end,
                  travelled > 0 ? 100.0 * end / travelled : 0.0, travelled);
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("odometry_trajectory", [&] { return run(argc, argv); });
}
