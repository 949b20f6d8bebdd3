#include "tum_benchmark_layout.h"

#include "bag_messages.h"

#include "view_selection/core/pose_interpolation.h"
#include "view_selection/io/tum_frames.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/ros/conversions.h"

#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <nav_msgs/Odometry.h>
#include <sensor_msgs/image_encodings.h>

#include <opencv2/imgproc.hpp>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <limits>

namespace view_selection::tum_to_bag {

namespace {

core::CameraPose link(const Eigen::Vector3d& t, const Eigen::Quaterniond& q) {
  core::CameraPose p;
  p.position = t;
  p.orientation = q;
  return p;
}

enum class Kind { kMocap, kFixedLink, kDepth, kColour };

struct Event {
  double bag_time;  ///< local (TUM-folder) seconds
  Kind kind;
  size_t index;     ///< mocap sample, fixed-link message, or position in `frames`
  size_t link = 0;  ///< kFixedLink: which link
};

/// A jitter in [-1, 1] that depends on the frame only (the same bag every time).
double jitterOf(size_t q) {
  const uint64_t h = (static_cast<uint64_t>(q) + 1) * 2654435761ULL % 1000003ULL;
  return 2.0 * static_cast<double>(h) / 1000002.0 - 1.0;
}

}  // namespace

std::vector<FixedLink> benchmarkFixedLinks(const std::string& camera_frame) {
  // Values in the spirit of the benchmark's launch files: the OpenNI driver's camera frame a
  // little off the motion-capture marker frame, the colour frame 4.5 cm to the side, and the
  // optical frame turned z-forward (x right, y down) from the x-forward frame.
  return {
      {"/kinect", "/openni_camera",
       link({-0.02, 0.005, 0.04},
            Eigen::Quaterniond(Eigen::AngleAxisd(0.03, Eigen::Vector3d::UnitZ())))},
      {"/openni_camera", "/openni_rgb_frame",
       link({0.0, -0.045, 0.0}, Eigen::Quaterniond::Identity())},
      {"/openni_rgb_frame", camera_frame,
       link(Eigen::Vector3d::Zero(), Eigen::Quaterniond(0.5, -0.5, 0.5, -0.5))},
  };
}

WrittenFrames writeBenchmarkLayout(rosbag::Bag& bag, const io::TumDataset& dataset,
                                   const std::vector<size_t>& frames,
                                   const BenchmarkLayoutOptions& o) {
  namespace enc = sensor_msgs::image_encodings;
  WrittenFrames written;
  if (frames.empty()) return written;
  const std::string gt_path = (std::filesystem::path(dataset.root) / "groundtruth.txt").string();
  std::vector<core::TimedPose> truth;
  for (const io::TumPoseEntry& e : io::readTumTrajectory(gt_path))
    truth.push_back({e.stamp, e.pose});
  std::sort(truth.begin(), truth.end(),
            [](const core::TimedPose& a, const core::TimedPose& b) { return a.stamp < b.stamp; });

  const std::vector<FixedLink> links = benchmarkFixedLinks(o.camera_frame);
  core::CameraPose optical_in_kinect;  // the fixed chain composed: optical-to-kinect
  for (const FixedLink& l : links)
    optical_in_kinect = core::composePoses(optical_in_kinect, l.transform);
  const core::CameraPose kinect_in_optical = core::inversePose(optical_in_kinect);

  // Every message as an event at its bag time, then written in bag-time order.
  const double first = dataset.frames[frames.front()].stamp;
  const double last = dataset.frames[frames.back()].stamp;
  // A phase, so that motion-capture samples never fall exactly on image stamps.
  const double mocap_start = first - o.mocap_lead + 0.0037;
  const double end = last + 0.5;
  std::vector<Event> events;
  std::vector<double> mocap_stamps;
  for (size_t k = 0;; ++k) {
    const double t = mocap_start + static_cast<double>(k) / o.mocap_rate;
    if (t > end) break;
    mocap_stamps.push_back(t);
    events.push_back({t + 0.001, Kind::kMocap, k});
  }
  for (size_t l = 0; l < links.size(); ++l) {
    const double phase = 0.011 + 0.031 * static_cast<double>(l);  // one publisher per link
    for (size_t k = 0;; ++k) {
      const double t = mocap_start + phase + static_cast<double>(k) * o.static_period;
      if (t > end) break;
      events.push_back({t, Kind::kFixedLink, k, l});
    }
  }
  std::vector<double> depth_stamps(frames.size());
  for (size_t q = 0; q < frames.size(); ++q) {
    const io::TumFrame& f = dataset.frames[frames[q]];
    events.push_back({f.stamp + o.image_latency, Kind::kColour, q});
    if (dataset.has_depth) {
      depth_stamps[q] = f.depth_stamp + o.depth_offset + o.depth_jitter * jitterOf(frames[q]);
      events.push_back({depth_stamps[q] + o.image_latency, Kind::kDepth, q});
    }
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const Event& a, const Event& b) { return a.bag_time < b.bag_time; });

  const auto rosTime = [&](double local, const std::string& what) {
    return toRosTime(local, what, o.stamp_offset);
  };
  const bool tty = isatty(fileno(stderr));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  uint32_t mocap_seq = 0, colour_seq = 0, depth_seq = 0;
  std::vector<uint32_t> link_seq(links.size(), 0);
  for (const Event& e : events) {
    const ros::Time bag_time = rosTime(e.bag_time, "bag time");
    if (e.kind == Kind::kMocap) {
      const double t = mocap_stamps[e.index];
      geometry_msgs::TransformStamped tf;
      tf.header.seq = mocap_seq++;
      tf.header.stamp = rosTime(t, "motion capture");
      tf.header.frame_id = o.world_frame;
      tf.child_frame_id = links.front().parent;
      tf.transform = ros_node::transformToMsg(
          core::composePoses(core::poseOnTrajectory(truth, t), kinect_in_optical));
      LegacyTfMessage msg;
      msg.message.transforms.push_back(tf);
      bag.write("/tf", bag_time, msg);
      if (o.pose_topics) {
        geometry_msgs::PoseStamped pose;
        pose.header = tf.header;
        pose.pose = ros_node::poseToMsg(ros_node::poseFromTransform(tf.transform));
        bag.write("/mocap/pose", bag_time, pose);
        nav_msgs::Odometry odometry;
        odometry.header = tf.header;
        odometry.child_frame_id = tf.child_frame_id;
        odometry.pose.pose = pose.pose;
        bag.write("/mocap/odometry", bag_time, odometry);
        geometry_msgs::PoseWithCovarianceStamped with_covariance;
        with_covariance.header = tf.header;
        with_covariance.pose.pose = pose.pose;
        bag.write("/mocap/pose_with_covariance", bag_time, with_covariance);
      }
    } else if (e.kind == Kind::kFixedLink) {
      const FixedLink& l = links[e.link];
      geometry_msgs::TransformStamped tf;
      tf.header.seq = link_seq[e.link]++;
      tf.header.stamp = rosTime(e.bag_time + o.static_period, "fixed link");
      tf.header.frame_id = l.parent;
      tf.child_frame_id = l.child;
      tf.transform = ros_node::transformToMsg(l.transform);
      LegacyTfMessage msg;
      msg.message.transforms.push_back(tf);
      bag.write("/tf", bag_time, msg);
    } else {
      const io::TumFrame& tum = dataset.frames[frames[e.index]];
      const std::string what =
          "frame " + std::to_string(frames[e.index]) + " (" + tum.rgb_path + ")";
      std_msgs::Header header;
      header.frame_id = o.camera_frame;  // depth is registered to colour in the benchmark's bags
      if (e.kind == Kind::kDepth) {
        header.seq = depth_seq++;
        header.stamp = rosTime(depth_stamps[e.index], what + " depth");
        const core::Frame frame = io::loadTumFrame(dataset, tum, {true, false});
        cv::Mat depth = images::matOf(frame.depth).clone();
        depth.setTo(nan, depth == 0.0f);
        bag.write("/camera/depth/camera_info", bag_time, cameraInfo(dataset.intrinsics, header));
        o.images.writeDepth(bag, bag_time, depth, header);
        continue;
      }
      header.seq = colour_seq++;
      header.stamp = rosTime(tum.stamp, what);
      const core::Frame frame = io::loadTumFrame(dataset, tum, {false, true});
      const cv::Mat image = images::matOf(frame.image);
      if (image.channels() != 3)
        throw core::InvalidInput(what + ": expected a colour image, got " +
                                 std::to_string(image.channels()) + " channel(s)");
      if (image.cols != dataset.intrinsics.width || image.rows != dataset.intrinsics.height)
        throw core::InvalidInput(what + ": image is " + std::to_string(image.cols) + "x" +
                                 std::to_string(image.rows) + " but the intrinsics say " +
                                 std::to_string(dataset.intrinsics.width) + "x" +
                                 std::to_string(dataset.intrinsics.height));
      cv::Mat rgb;
      cv::cvtColor(image, rgb, cv::COLOR_BGR2RGB);
      bag.write("/camera/rgb/camera_info", bag_time, cameraInfo(dataset.intrinsics, header));
      o.images.writeColour(bag, bag_time, rgb, header);
      if (written.frames == 0) written.first = header.stamp.toSec();
      written.last = header.stamp.toSec();
      ++written.frames;
      reportProgress(written.frames, frames.size(), tty, o.quiet);
    }
  }
  return written;
}

}  // namespace view_selection::tum_to_bag
