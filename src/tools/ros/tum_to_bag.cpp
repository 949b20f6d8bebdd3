// tum_to_bag: a TUM RGB-D folder (rgb.txt, depth.txt, groundtruth.txt) to a bag with the TUM
// benchmark's topics, so that the node can be tested on a replay exactly as users run it on the
// benchmark's bags. --layout simple (the default): one pose per frame at the image stamp, the
// TUM stamps as they are; --layout tum: as the benchmark's own bags are recorded
// (tum_benchmark_layout.h). Frame ids carry the leading '/' that the TUM bags write.
#include "../command_line.h"
#include "bag_messages.h"
#include "tum_benchmark_layout.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/tum_frames.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/ros/conversions.h"

#include <geometry_msgs/PoseStamped.h>
#include <ros/time.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_msgs/TFMessage.h>

#include <opencv2/imgproc.hpp>

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <limits>
#include <vector>

namespace fs = std::filesystem;
using namespace view_selection::io;
namespace images = view_selection::images;
namespace ros_node = view_selection::ros_node;
namespace core = view_selection::core;
using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;
using namespace view_selection::tum_to_bag;

namespace {

const char* kUsage = R"(usage: tum_to_bag --dataset DIR --out BAG [options]

Writes a TUM RGB-D layout folder (rgb.txt, depth.txt, groundtruth.txt, camera.yaml) as a bag
with the TUM benchmark's topics:
  /camera/rgb/image_color     sensor_msgs/Image, rgb8
  /camera/rgb/camera_info     sensor_msgs/CameraInfo (plumb_bob, D = 0)
  /camera/depth/image         sensor_msgs/Image, 32FC1 metres, NaN where depth is missing
  /camera/depth/camera_info   sensor_msgs/CameraInfo (depth is registered to the colour camera)
  /tf                         the ground truth (see the layouts)

--layout simple (default): stamps are the TUM stamps and bag time = stamp; /tf (tf2_msgs) holds
  world frame -> camera frame at each image's stamp, and /camera/pose (PoseStamped) the same
  pose. Each frame carries the ground truth associated with its colour image (nearest within
  the association tolerance, as select_views uses it), so the node sees select_views's frames.
--layout tum: as the benchmark's own bags are recorded: /tf of type tf/tfMessage, no
  /tf_static, the chain /world -> /kinect (motion capture at --mocap-rate from the ground truth,
  starting --mocap-lead s before the first image) -> /openni_camera -> /openni_rgb_frame ->
  /openni_rgb_optical_frame, the fixed links re-sent every --static-period s stamped that far
  ahead; depth stamped --depth-offset (+- --depth-jitter) from colour; bag time 20 ms after each
  image's stamp; stamps moved by --stamp-offset; bz2 by default.

options:
  --dataset DIR             TUM layout folder (required)
  --out BAG                 bag to write (required; overwritten)
  --layout MODE             simple | tum (default simple)
  --max-frames N            only the first N associated frames (as select_views --max-frames)
  --every N                 only every Nth of those frames (default 1: all)
  --max-time-difference S   rgb/depth/pose association tolerance [s] (default 0.02)
  --world-frame NAME        default /world
  --camera-frame NAME       default /openni_rgb_optical_frame
  --compression MODE        none | lz4 | bz2 (default lz4; bz2 with --layout tum)
  --stamp-offset N          tum: whole seconds added to every stamp (default: 1305030000 when
                            the folder's stamps are below 1e9, as the redkitchen's 1000 s, else 0)
  --depth-offset S          tum: depth stamp minus colour stamp [s] (default -0.015)
  --depth-jitter S          tum: plus a fixed per-frame jitter within +-S [s] (default 0.002)
  --mocap-rate HZ           tum: motion-capture rate (default 100)
  --mocap-lead S            tum: motion capture starts S before the first image (default 3)
  --static-period S         tum: period of the fixed links (default 0.1)
  --compressed              the images as a robot records them with image_transport_plugins:
                            colour as `compressed` JPEG on /camera/rgb/image_color/compressed
                            (sensor_msgs/CompressedImage, format "rgb8; jpeg compressed bgr8"),
                            depth as `compressedDepth` on /camera/depth/image/compressedDepth
                            (32FC1 as quantised inverse depth in a PNG); replay with
                            tum_replay.launch image_transport:=compressed
                            depth_image_transport:=compressedDepth
  --jpeg-quality Q          with --compressed: JPEG quality 1-100 (default 80, the plugin's)
  --pose-topics             tum: also the motion capture (/kinect in the world frame) as
                            /mocap/pose (PoseStamped), /mocap/odometry (Odometry) and
                            /mocap/pose_with_covariance, for the node's topic pose sources
  --no-poses                simple: no /tf and no /camera/pose, only images, depth and camera_info
                            (a bag recorded without a pose source: rgbd_odometry tracks it)
  --quiet                   no progress lines
  --help                    this text
)";

/// Where --layout tum puts a folder whose stamps are not Unix times (the redkitchen's 1000 s):
/// 1000 s becomes 1305031000 s, the days of the freiburg1 recordings.
constexpr long long kTumStampOffset = 1305030000LL;

struct Options {
  std::string dataset;
  std::string out;
  long max_frames = 0;
  long every = 1;
  double max_time_difference = 0.02;
  std::string world_frame = "/world";
  std::string camera_frame = "/openni_rgb_optical_frame";
  std::string compression = "lz4";
  std::string layout = "simple";
  bool stamp_offset_given = false;
  bool no_poses = false;  ///< simple: images and depth only (a pose source must track them)
  BenchmarkLayoutOptions tum;
  bool quiet = false;
};

Options parse(int argc, char** argv) {
  const CommandLine cli(
      argc, argv,
      {"dataset", "out", "layout", "max-frames", "every", "max-time-difference", "world-frame",
       "camera-frame", "compression", "stamp-offset", "depth-offset", "depth-jitter", "mocap-rate",
       "mocap-lead", "static-period", "jpeg-quality"},
      {"quiet", "help", "pose-topics", "compressed", "no-poses"});
  if (cli.flag("help")) {
    std::cout << kUsage;
    std::exit(0);
  }
  Options o;
  if (!cli.has("dataset")) throw UsageError("--dataset DIR is required (see --help)");
  if (!cli.has("out")) throw UsageError("--out BAG is required (see --help)");
  o.dataset = *cli.text("dataset");
  o.out = *cli.text("out");
  o.max_frames = cli.integer("max-frames", 0, 1, 100000000);
  o.every = cli.integer("every", 1, 1, 1000000);
  o.max_time_difference = cli.real("max-time-difference", o.max_time_difference, 0.0, 10.0);
  o.world_frame = cli.text("world-frame", o.world_frame);
  o.camera_frame = cli.text("camera-frame", o.camera_frame);
  if (o.world_frame.empty() || o.camera_frame.empty())
    throw UsageError("frame names must not be empty");
  if (o.world_frame == o.camera_frame)
    throw UsageError("--world-frame and --camera-frame must differ");
  o.layout = cli.choice("layout", o.layout, {"simple", "tum"});
  o.compression =
      cli.choice("compression", o.layout == "tum" ? "bz2" : o.compression, {"none", "lz4", "bz2"});
  for (const char* name : {"stamp-offset", "depth-offset", "depth-jitter", "mocap-rate",
                           "mocap-lead", "static-period"})
    if (cli.has(name) && o.layout != "tum")
      throw UsageError(std::string("--") + name + " is an option of --layout tum");
  o.stamp_offset_given = cli.has("stamp-offset");
  o.tum.stamp_offset = cli.integer("stamp-offset", 0, -2000000000L, 4000000000L);
  o.tum.depth_offset = cli.real("depth-offset", o.tum.depth_offset, -1.0, 1.0);
  o.tum.depth_jitter = cli.real("depth-jitter", o.tum.depth_jitter, 0.0, 0.1);
  o.tum.mocap_rate = cli.real("mocap-rate", o.tum.mocap_rate, 1.0, 10000.0);
  o.tum.mocap_lead = cli.real("mocap-lead", o.tum.mocap_lead, 0.0, 3600.0);
  o.tum.static_period = cli.real("static-period", o.tum.static_period, 0.001, 10.0);
  if (cli.flag("pose-topics") && o.layout != "tum")
    throw UsageError("--pose-topics is an option of --layout tum");
  o.tum.pose_topics = cli.flag("pose-topics");
  o.no_poses = cli.flag("no-poses");
  if (o.no_poses && o.layout != "simple") throw UsageError("--no-poses is an option of --layout simple");
  o.tum.images.compressed = cli.flag("compressed");
  if (cli.has("jpeg-quality") && !o.tum.images.compressed)
    throw UsageError("--jpeg-quality is an option of --compressed");
  o.tum.images.jpeg_quality =
      static_cast<int>(cli.integer("jpeg-quality", o.tum.images.jpeg_quality, 1, 100));
  o.tum.world_frame = o.world_frame;
  o.tum.camera_frame = o.camera_frame;
  o.quiet = cli.flag("quiet");
  o.tum.quiet = o.quiet;
  return o;
}

void discard(rosbag::Bag& bag, const fs::path& path) {
  try {
    bag.close();
  } catch (...) {
  }
  std::error_code ec;
  fs::remove(path, ec);
}

/// --layout simple: per frame, the pose at the image stamp on /tf and /camera/pose, then depth
/// and colour; bag time = stamp.
WrittenFrames writeSimpleLayout(rosbag::Bag& bag, const TumDataset& dataset,
                                const std::vector<size_t>& frames, const Options& o) {
  const bool tty = isatty(fileno(stderr));
  WrittenFrames written;
  uint32_t seq = 0;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (const size_t q : frames) {
    const TumFrame& tum = dataset.frames[q];
    const core::Frame frame = loadTumFrame(dataset, tum, {true, true});
    const cv::Mat image = images::matOf(frame.image), depth_m = images::matOf(frame.depth);
    const std::string what = "frame " + std::to_string(q) + " (" + tum.rgb_path + ")";
    if (image.cols != dataset.intrinsics.width || image.rows != dataset.intrinsics.height)
      throw core::InvalidInput(what + ": image is " + std::to_string(image.cols) + "x" +
                               std::to_string(image.rows) + " but the intrinsics say " +
                               std::to_string(dataset.intrinsics.width) + "x" +
                               std::to_string(dataset.intrinsics.height));
    const ros::Time stamp = toRosTime(tum.stamp, what);

    std_msgs::Header header;
    header.seq = seq++;
    header.stamp = stamp;
    header.frame_id = o.camera_frame;

    // Ground truth first, so that a pose is in the tf buffer when its image arrives.
    if (!o.no_poses) {
      geometry_msgs::TransformStamped t;
      t.header.seq = header.seq;
      t.header.stamp = stamp;
      t.header.frame_id = o.world_frame;
      t.child_frame_id = o.camera_frame;
      t.transform = ros_node::transformToMsg(tum.pose);
      tf2_msgs::TFMessage tf;
      tf.transforms.push_back(t);
      bag.write("/tf", stamp, tf);

      geometry_msgs::PoseStamped pose;
      pose.header = t.header;
      pose.pose = ros_node::poseToMsg(tum.pose);
      bag.write("/camera/pose", stamp, pose);
    }

    if (!depth_m.empty()) {
      std_msgs::Header depth_header = header;
      depth_header.stamp = toRosTime(tum.depth_stamp, what + " depth");
      cv::Mat depth = depth_m.clone();
      depth.setTo(nan, depth == 0.0f);  // TUM's 32FC1 bags mark missing depth with NaN
      bag.write("/camera/depth/camera_info", depth_header.stamp,
                cameraInfo(dataset.intrinsics, depth_header));
      o.tum.images.writeDepth(bag, depth_header.stamp, depth, depth_header);
    }

    if (image.channels() != 3)
      throw core::InvalidInput(what + ": expected a colour image, got " +
                               std::to_string(image.channels()) + " channel(s)");
    cv::Mat rgb;
    cv::cvtColor(image, rgb, cv::COLOR_BGR2RGB);
    bag.write("/camera/rgb/camera_info", stamp, cameraInfo(dataset.intrinsics, header));
    o.tum.images.writeColour(bag, stamp, rgb, header);

    if (written.frames == 0) written.first = tum.stamp;
    written.last = tum.stamp;
    ++written.frames;
    reportProgress(written.frames, frames.size(), tty, o.quiet);
  }
  return written;
}

int run(Options o) {
  TumDatasetOptions dataset_options;
  dataset_options.max_time_difference = o.max_time_difference;
  const TumDataset dataset = loadTumDataset(o.dataset, dataset_options);
  const size_t total =
      o.max_frames > 0 ? std::min<size_t>(dataset.frames.size(), static_cast<size_t>(o.max_frames))
                       : dataset.frames.size();
  std::vector<size_t> frames;
  for (size_t q = 0; q < total; q += static_cast<size_t>(o.every)) frames.push_back(q);
  if (!dataset.has_depth)
    std::fprintf(stderr,
                 "tum_to_bag: warning: '%s' has no depth.txt; the bag has no depth topics\n",
                 o.dataset.c_str());
  // The benchmark's stamps are Unix times (~1.3e9 s); folders with small stamps are moved there.
  if (o.layout == "tum" && !o.stamp_offset_given && dataset.frames.front().stamp < 1e9)
    o.tum.stamp_offset = kTumStampOffset;

  const fs::path out(o.out);
  if (out.has_parent_path()) {
    std::error_code ec;
    fs::create_directories(out.parent_path(), ec);
    if (ec)
      throw core::IoError("cannot create folder '" + out.parent_path().string() +
                          "': " + ec.message());
  }
  rosbag::Bag bag;
  try {
    bag.open(o.out, rosbag::bagmode::Write);
  } catch (const rosbag::BagException& e) {
    throw core::IoError("cannot write bag '" + o.out + "': " + e.what());
  }
  bag.setCompression(o.compression == "lz4"   ? rosbag::compression::LZ4
                     : o.compression == "bz2" ? rosbag::compression::BZ2
                                              : rosbag::compression::Uncompressed);
  WrittenFrames written;
  try {
    written = o.layout == "tum" ? writeBenchmarkLayout(bag, dataset, frames, o.tum)
                                : writeSimpleLayout(bag, dataset, frames, o);
  } catch (const rosbag::BagException& e) {
    discard(bag, out);
    throw core::IoError("writing bag '" + o.out + "': " + e.what());
  } catch (...) {
    discard(bag, out);  // no half-written bag left behind that looks like a result
    throw;
  }
  bag.close();
  std::printf(
      "tum_to_bag: wrote %s (layout %s): %zu frames (%.3f s to %.3f s) of %zu associated in %s, "
      "depth %s, images %s, intrinsics from %s%s\n",
      o.out.c_str(), o.layout.c_str(), written.frames, written.first, written.last,
      dataset.frames.size(), o.dataset.c_str(), dataset.has_depth ? "yes" : "no",
      o.tum.images.compressed ? "compressed (JPEG, compressedDepth)" : "raw",
      dataset.intrinsics_source.c_str(),
      o.layout == "tum" ? (", stamps moved by " + std::to_string(o.tum.stamp_offset) + " s").c_str()
                        : "");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("tum_to_bag", [&] { return run(parse(argc, argv)); });
}
