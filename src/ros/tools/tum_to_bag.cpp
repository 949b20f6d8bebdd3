// tum_to_bag: a TUM RGB-D folder (rgb.txt, depth.txt, groundtruth.txt) to a bag in the TUM
// benchmark's own topic layout, so that the node can be tested on a replay exactly as users run
// it on the benchmark's bags. Stamps are the TUM stamps; frame ids carry the leading '/' that the
// TUM bags write.
#include "../../tools/command_line.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/tum_frames.h"
#include "view_selection/points/image_conversion.h"
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

namespace fs = std::filesystem;
using namespace view_selection::io;
namespace points = view_selection::points;
namespace ros_node = view_selection::ros_node;
namespace core = view_selection::core;
using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;

namespace {

const char* kUsage = R"(usage: tum_to_bag --dataset DIR --out BAG [options]

Writes a TUM RGB-D layout folder (rgb.txt, depth.txt, groundtruth.txt, camera.yaml) as a bag
with the TUM benchmark's topics, stamped with the TUM stamps:
  /camera/rgb/image_color     sensor_msgs/Image, rgb8
  /camera/rgb/camera_info     sensor_msgs/CameraInfo
  /camera/depth/image         sensor_msgs/Image, 32FC1 metres, NaN where depth is missing
  /camera/depth/camera_info   sensor_msgs/CameraInfo (depth is registered to the colour camera)
  /tf                         ground truth, world frame -> camera frame, at each image's stamp
  /camera/pose                geometry_msgs/PoseStamped, the same pose (for ~pose_source topic)
Each frame carries the ground-truth pose associated with its colour image (nearest within the
association tolerance, as select_views uses it), so the node sees exactly select_views's frames.

options:
  --dataset DIR             TUM layout folder (required)
  --out BAG                 bag to write (required; overwritten)
  --max-frames N            only the first N associated frames (as select_views --max-frames)
  --every N                 only every Nth of those frames (default 1: all)
  --max-time-difference S   rgb/depth/pose association tolerance [s] (default 0.02)
  --world-frame NAME        default /world
  --camera-frame NAME       default /openni_rgb_optical_frame
  --compression MODE        none | lz4 | bz2 (default lz4)
  --quiet                   no progress lines
  --help                    this text
)";

struct Options {
  std::string dataset;
  std::string out;
  long max_frames = 0;
  long every = 1;
  double max_time_difference = 0.02;
  std::string world_frame = "/world";
  std::string camera_frame = "/openni_rgb_optical_frame";
  std::string compression = "lz4";
  bool quiet = false;
};

Options parse(int argc, char** argv) {
  const CommandLine cli(argc, argv,
                        {"dataset", "out", "max-frames", "every", "max-time-difference",
                         "world-frame", "camera-frame", "compression"},
                        {"quiet", "help"});
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
  o.compression = cli.choice("compression", o.compression, {"none", "lz4", "bz2"});
  o.quiet = cli.flag("quiet");
  return o;
}

ros::Time toRosTime(double stamp, const std::string& what) {
  // ros::Time holds unsigned 32-bit seconds; TUM stamps are Unix seconds.
  if (!std::isfinite(stamp) || stamp < 0.0 || stamp >= 4294967295.0)
    throw core::InvalidInput(what + ": stamp " + std::to_string(stamp) + " cannot be a ROS time");
  // Round to the nanosecond (the TUM lists have 6 decimals), not ros::Time(double)'s truncation.
  const double whole = std::floor(stamp);
  long long nsec = std::llround((stamp - whole) * 1e9);
  auto sec = static_cast<uint32_t>(whole);
  if (nsec >= 1000000000LL) {
    ++sec;
    nsec -= 1000000000LL;
  }
  return ros::Time(sec, static_cast<uint32_t>(nsec));
}

sensor_msgs::CameraInfo cameraInfo(const core::PinholeIntrinsics& k,
                                   const std_msgs::Header& header) {
  sensor_msgs::CameraInfo info;
  info.header = header;
  info.width = static_cast<uint32_t>(k.width);
  info.height = static_cast<uint32_t>(k.height);
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);  // TUM's images are used as they are; the benchmark lists no undistortion
  info.K = {k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0};
  info.R = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  info.P = {k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0};
  return info;
}

sensor_msgs::Image imageMessage(const cv::Mat& mat, const std::string& encoding,
                                const std_msgs::Header& header) {
  sensor_msgs::Image msg;
  msg.header = header;
  msg.height = static_cast<uint32_t>(mat.rows);
  msg.width = static_cast<uint32_t>(mat.cols);
  msg.encoding = encoding;
  msg.is_bigendian = 0;
  msg.step = static_cast<uint32_t>(mat.cols * mat.elemSize());
  msg.data.resize(static_cast<size_t>(msg.step) * mat.rows);
  for (int r = 0; r < mat.rows; ++r)
    std::memcpy(msg.data.data() + static_cast<size_t>(r) * msg.step, mat.ptr(r), msg.step);
  return msg;
}

void discard(rosbag::Bag& bag, const fs::path& path) {
  try {
    bag.close();
  } catch (...) {
  }
  std::error_code ec;
  fs::remove(path, ec);
}

int run(const Options& o) {
  TumDatasetOptions dataset_options;
  dataset_options.max_time_difference = o.max_time_difference;
  const TumDataset dataset = loadTumDataset(o.dataset, dataset_options);
  const size_t total =
      o.max_frames > 0 ? std::min<size_t>(dataset.frames.size(), static_cast<size_t>(o.max_frames))
                       : dataset.frames.size();
  if (!dataset.has_depth)
    std::fprintf(stderr,
                 "tum_to_bag: warning: '%s' has no depth.txt; the bag has no depth topics\n",
                 o.dataset.c_str());

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

  const bool tty = isatty(fileno(stderr));
  size_t written = 0;
  double first = 0.0, last = 0.0;
  uint32_t seq = 0;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  try {
    for (size_t q = 0; q < total; q += static_cast<size_t>(o.every)) {
      const TumFrame& tum = dataset.frames[q];
      const core::Frame frame = loadTumFrame(dataset, tum, {true, true});
      const cv::Mat image = points::matOf(frame.image), depth_m = points::matOf(frame.depth);
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

      if (!depth_m.empty()) {
        std_msgs::Header depth_header = header;
        depth_header.stamp = toRosTime(tum.depth_stamp, what + " depth");
        cv::Mat depth = depth_m.clone();
        depth.setTo(nan, depth == 0.0f);  // TUM's 32FC1 bags mark missing depth with NaN
        bag.write("/camera/depth/camera_info", depth_header.stamp,
                  cameraInfo(dataset.intrinsics, depth_header));
        bag.write("/camera/depth/image", depth_header.stamp,
                  imageMessage(depth, sensor_msgs::image_encodings::TYPE_32FC1, depth_header));
      }

      cv::Mat rgb;
      if (image.channels() == 3) {
        cv::cvtColor(image, rgb, cv::COLOR_BGR2RGB);
      } else {
        throw core::InvalidInput(what + ": expected a colour image, got " +
                                 std::to_string(image.channels()) + " channel(s)");
      }
      bag.write("/camera/rgb/camera_info", stamp, cameraInfo(dataset.intrinsics, header));
      bag.write("/camera/rgb/image_color", stamp,
                imageMessage(rgb, sensor_msgs::image_encodings::RGB8, header));

      if (written == 0) first = tum.stamp;
      last = tum.stamp;
      ++written;
      if (!o.quiet && (written % 50 == 0 || q + static_cast<size_t>(o.every) >= total)) {
        std::fprintf(stderr, "%s  frame %zu/%zu%s", tty ? "\r" : "", q + 1, total, tty ? "" : "\n");
        if (tty && q + static_cast<size_t>(o.every) >= total) std::fprintf(stderr, "\n");
      }
    }
  } catch (const rosbag::BagException& e) {
    discard(bag, out);
    throw core::IoError("writing bag '" + o.out + "': " + e.what());
  } catch (...) {
    discard(bag, out);  // no half-written bag left behind that looks like a result
    throw;
  }
  bag.close();
  std::printf(
      "tum_to_bag: wrote %s: %zu frames (%.3f s to %.3f s) of %zu associated in %s, depth %s, "
      "intrinsics from %s\n",
      o.out.c_str(), written, first, last, dataset.frames.size(), o.dataset.c_str(),
      dataset.has_depth ? "yes" : "no", dataset.intrinsics_source.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("tum_to_bag", [&] { return run(parse(argc, argv)); });
}
