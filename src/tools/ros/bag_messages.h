// Messages tum_to_bag writes, shared by its two layouts: stamps, camera_info, images, and /tf in
// the old tf/tfMessage type that the TUM benchmark's bags carry. Header-only, tum_to_bag only.
#pragma once

#include "view_selection/core/exceptions.h"
#include "view_selection/core/types.h"
#include "view_selection/ros/compressed_images.h"

#include <ros/message_traits.h>
#include <ros/serialization.h>
#include <ros/time.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_msgs/TFMessage.h>

#include <opencv2/core.hpp>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>

namespace view_selection::tum_to_bag {

/// A TUM stamp [s] as a ROS time, rounded to the nanosecond (the lists have 6 decimals; not
/// ros::Time(double)'s truncation), plus `offset_seconds` whole seconds. Throws InvalidInput
/// when it is no ROS time (unsigned 32-bit seconds).
inline ros::Time toRosTime(double stamp, const std::string& what, long long offset_seconds = 0) {
  const double whole = std::floor(stamp);
  const double shifted = whole + static_cast<double>(offset_seconds);
  if (!std::isfinite(stamp) || shifted < 0.0 || shifted >= 4294967295.0)
    throw core::InvalidInput(what + ": stamp " + std::to_string(stamp) + " cannot be a ROS time");
  long long nsec = std::llround((stamp - whole) * 1e9);
  auto sec = static_cast<uint32_t>(shifted);
  if (nsec >= 1000000000LL) {
    ++sec;
    nsec -= 1000000000LL;
  }
  return ros::Time(sec, static_cast<uint32_t>(nsec));
}

/// The "frame i/n" line on stderr every 50 frames and at the last (overwritten in place on a
/// terminal); nothing when `quiet`.
inline void reportProgress(size_t written, size_t total, bool tty, bool quiet) {
  if (quiet || !(written % 50 == 0 || written == total)) return;
  std::fprintf(stderr, "%s  frame %zu/%zu%s", tty ? "\r" : "", written, total, tty ? "" : "\n");
  if (tty && written == total) std::fprintf(stderr, "\n");
}

inline sensor_msgs::CameraInfo cameraInfo(const core::PinholeIntrinsics& k,
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

inline sensor_msgs::Image imageMessage(const cv::Mat& mat, const std::string& encoding,
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

/// How the colour and depth images are written: raw sensor_msgs/Image on the topics, or
/// (--compressed) as a robot records them with image_transport_plugins: the colour image as
/// `compressed` JPEG on <topic>/compressed, the 32FC1 depth as `compressedDepth` (quantised
/// inverse depth in a PNG) on <topic>/compressedDepth.
struct ImageTopics {
  bool compressed = false;
  int jpeg_quality = 80;  ///< compressed_image_transport's default
  std::string colour_topic = "/camera/rgb/image_color";
  std::string depth_topic = "/camera/depth/image";

  /// `rgb`: 8-bit RGB.
  void writeColour(rosbag::Bag& bag, const ros::Time& time, const cv::Mat& rgb,
                   const std_msgs::Header& header) const {
    namespace enc = sensor_msgs::image_encodings;
    if (!compressed) return bag.write(colour_topic, time, imageMessage(rgb, enc::RGB8, header));
    sensor_msgs::CompressedImage msg =
        ros_node::encodeCompressedImage(rgb, enc::RGB8, "jpeg", jpeg_quality);
    msg.header = header;
    bag.write(colour_topic + "/compressed", time, msg);
  }
  /// `depth`: CV_32FC1 metres, NaN where there is none.
  void writeDepth(rosbag::Bag& bag, const ros::Time& time, const cv::Mat& depth,
                  const std_msgs::Header& header) const {
    if (!compressed)
      return bag.write(depth_topic, time,
                       imageMessage(depth, sensor_msgs::image_encodings::TYPE_32FC1, header));
    sensor_msgs::CompressedImage msg = ros_node::encodeCompressedDepth(depth);
    msg.header = header;
    bag.write(depth_topic + "/compressedDepth", time, msg);
  }
};

/// tf2_msgs/TFMessage written under the type name "tf/tfMessage", as the TUM bags (recorded
/// before tf2) carry it: the definition and MD5 sum are the same, so tf2 listeners take it.
struct LegacyTfMessage {
  tf2_msgs::TFMessage message;
};

}  // namespace view_selection::tum_to_bag

namespace ros::message_traits {
template <>
struct MD5Sum<view_selection::tum_to_bag::LegacyTfMessage> {
  static const char* value() { return MD5Sum<tf2_msgs::TFMessage>::value(); }
  static const char* value(const view_selection::tum_to_bag::LegacyTfMessage&) { return value(); }
};
template <>
struct DataType<view_selection::tum_to_bag::LegacyTfMessage> {
  static const char* value() { return "tf/tfMessage"; }
  static const char* value(const view_selection::tum_to_bag::LegacyTfMessage&) { return value(); }
};
template <>
struct Definition<view_selection::tum_to_bag::LegacyTfMessage> {
  static const char* value() { return Definition<tf2_msgs::TFMessage>::value(); }
  static const char* value(const view_selection::tum_to_bag::LegacyTfMessage&) { return value(); }
};
}  // namespace ros::message_traits

namespace ros::serialization {
template <>
struct Serializer<view_selection::tum_to_bag::LegacyTfMessage> {
  template <typename Stream, typename T>
  inline static void allInOne(Stream& stream, T m) {
    stream.next(m.message);
  }
  ROS_DECLARE_ALLINONE_SERIALIZER
};
}  // namespace ros::serialization
