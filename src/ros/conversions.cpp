#include "view_selection/ros/conversions.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/images/image_conversion.h"

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/image_encodings.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sstream>

namespace enc = sensor_msgs::image_encodings;

namespace view_selection::ros_node {

core::PinholeIntrinsics intrinsicsFromCameraInfo(const sensor_msgs::CameraInfo& info) {
  core::PinholeIntrinsics k;
  k.fx = info.K[0];
  k.fy = info.K[4];
  k.cx = info.K[2];
  k.cy = info.K[5];
  k.width = static_cast<int>(info.width);
  k.height = static_cast<int>(info.height);
  if (!k.isValid() || !std::isfinite(k.cx) || !std::isfinite(k.cy)) {
    std::ostringstream s;
    s << "camera_info is unusable (K: fx=" << k.fx << " fy=" << k.fy << " cx=" << k.cx
      << " cy=" << k.cy << ", size " << info.width << "x" << info.height
      << "): focal lengths must be positive and finite and the size non-zero";
    throw core::InvalidInput(s.str());
  }
  return k;
}

void checkImageMessage(const sensor_msgs::Image& msg, const std::string& what) {
  std::ostringstream s;
  if (msg.width == 0 || msg.height == 0) {
    s << what << " is empty (" << msg.width << "x" << msg.height << ")";
    throw core::InvalidInput(s.str());
  }
  int channels = 0, bit_depth = 0;
  try {
    channels = enc::numChannels(msg.encoding);
    bit_depth = enc::bitDepth(msg.encoding);
  } catch (const std::exception&) {
    throw core::InvalidInput(what + " has unknown encoding '" + msg.encoding + "'");
  }
  if (channels <= 0 || bit_depth <= 0)
    throw core::InvalidInput(what + " has unusable encoding '" + msg.encoding + "'");
  // In 64 bits: "8UC<n>" encodings may name any channel count (fuzz/regressions/messages).
  const uint64_t pixel_bytes =
      static_cast<uint64_t>(channels) * static_cast<uint64_t>(bit_depth / 8);
  const uint64_t row_bytes = static_cast<uint64_t>(msg.width) * pixel_bytes;
  if (msg.step < row_bytes) {
    s << what << " step " << msg.step << " is less than width " << msg.width << " x " << pixel_bytes
      << " bytes of '" << msg.encoding << "'";
    throw core::InvalidInput(s.str());
  }
  // OpenCV (cv_bridge too) reads rows only at whole elements apart (fuzz/regressions/messages).
  if (msg.step % static_cast<uint32_t>(std::max(1, bit_depth / 8)) != 0) {
    s << what << " step " << msg.step << " is not a multiple of its " << bit_depth / 8
      << "-byte elements ('" << msg.encoding << "')";
    throw core::InvalidInput(s.str());
  }
  if (msg.data.size() < static_cast<uint64_t>(msg.step) * msg.height) {
    s << what << " holds " << msg.data.size() << " bytes, but step " << msg.step << " x height "
      << msg.height << " needs " << static_cast<uint64_t>(msg.step) * msg.height;
    throw core::InvalidInput(s.str());
  }
  if (what == "image" && !enc::isColor(msg.encoding) && !enc::isMono(msg.encoding) &&
      !enc::isBayer(msg.encoding))
    throw core::InvalidInput("image encoding '" + msg.encoding +
                             "' is not a colour or grey image (expected rgb8, bgr8, mono8, ...)");
  const bool little = [] {
    const uint16_t one = 1;
    return *reinterpret_cast<const uint8_t*>(&one) == 1;
  }();
  if (bit_depth > 8 && msg.is_bigendian == little)
    throw core::InvalidInput(what + " is " + (msg.is_bigendian ? "big" : "little") +
                             "-endian, which this machine does not read natively");
}

Eigen::Matrix3Xd mapPointsFromCloud(const sensor_msgs::PointCloud2& cloud) {
  uint32_t offsets[3] = {0, 0, 0};
  const char* names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    const sensor_msgs::PointField* field = nullptr;
    for (const auto& f : cloud.fields)
      if (f.name == names[a]) field = &f;
    if (!field) throw core::InvalidInput(std::string("the cloud has no field '") + names[a] + "'");
    if (field->datatype != sensor_msgs::PointField::FLOAT32 || field->count < 1)
      throw core::InvalidInput(std::string("the cloud's field '") + names[a] + "' is not float32");
    if (static_cast<uint64_t>(field->offset) + 4 > cloud.point_step)
      throw core::InvalidInput(std::string("the cloud's field '") + names[a] +
                               "' lies outside its point_step");
    offsets[a] = field->offset;
  }
  if (cloud.is_bigendian) throw core::InvalidInput("the cloud is big-endian");
  const uint64_t width = cloud.width, height = cloud.height;
  // No points: done (not 4e9 empty rows, fuzz/regressions/messages/cloud_zero_width_4e9_rows).
  if (width == 0 || height == 0) return Eigen::Matrix3Xd(3, 0);
  if (static_cast<uint64_t>(cloud.point_step) * width > cloud.row_step ||
      static_cast<uint64_t>(cloud.row_step) * height > cloud.data.size())
    throw core::InvalidInput("the cloud's data is shorter than its width, height and steps say");
  Eigen::Matrix3Xd points(3, static_cast<Eigen::Index>(width * height));
  Eigen::Index kept = 0;
  for (uint64_t r = 0; r < height; ++r) {
    for (uint64_t c = 0; c < width; ++c) {
      const uint8_t* p = cloud.data.data() + r * cloud.row_step + c * cloud.point_step;
      float v[3];
      for (int a = 0; a < 3; ++a) std::memcpy(&v[a], p + offsets[a], sizeof(float));
      if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
        continue;  // organised clouds pad with NaN
      points.col(kept++) = Eigen::Vector3d(v[0], v[1], v[2]);
    }
  }
  points.conservativeResize(3, kept);
  return points;
}

cv::Mat imageView(const sensor_msgs::Image& msg) {
  int type = -1;
  try {
    type = cv_bridge::getCvType(msg.encoding);
  } catch (const std::exception& e) {
    throw core::InvalidInput("cannot read encoding '" + msg.encoding + "': " + e.what());
  }
  try {
    return cv::Mat(static_cast<int>(msg.height), static_cast<int>(msg.width), type,
                   const_cast<uint8_t*>(msg.data.data()), msg.step);
  } catch (const cv::Exception& e) {
    throw core::InvalidInput("cannot view the '" + msg.encoding + "' image: " + e.what());
  }
}

namespace {

cv_bridge::CvImageConstPtr shareForCore(const sensor_msgs::ImageConstPtr& msg) {
  try {
    if (msg->encoding == enc::MONO8 || msg->encoding == enc::BGR8) return cv_bridge::toCvShare(msg);
    if (enc::isColor(msg->encoding) || enc::isMono(msg->encoding) || enc::isBayer(msg->encoding))
      return cv_bridge::toCvShare(msg, enc::isMono(msg->encoding) ? enc::MONO8 : enc::BGR8);
  } catch (const cv_bridge::Exception& e) {
    throw core::InvalidInput("image with encoding '" + msg->encoding +
                             "' cannot be converted: " + e.what());
  } catch (const cv::Exception& e) {
    throw core::InvalidInput("image with encoding '" + msg->encoding +
                             "' cannot be converted: " + e.what());
  }
  throw core::InvalidInput("image encoding '" + msg->encoding +
                           "' is not a colour or grey image (expected rgb8, bgr8, mono8, ...)");
}

/// A std::shared_ptr that keeps a boost::shared_ptr (ROS messages, cv_bridge images) alive.
template <typename T>
std::shared_ptr<const void> keepAlive(const boost::shared_ptr<T>& p) {
  return std::shared_ptr<const void>(p.get(), [p](const void*) {});
}

}  // namespace

cv::Mat imageForCore(const sensor_msgs::ImageConstPtr& msg) { return shareForCore(msg)->image; }

core::ColourImage colourImageForCore(const sensor_msgs::ImageConstPtr& msg) {
  const cv_bridge::CvImageConstPtr shared = shareForCore(msg);
  core::ColourImage view = images::colourImageOf(shared->image);
  view.owner = keepAlive(shared);  // keeps the message (or the converted copy) alive with the view
  return view;
}

core::ColourImage borrowedImageView(const sensor_msgs::ImageConstPtr& msg) {
  core::ColourImage view;
  view.data = msg->data.data();
  view.width = static_cast<int>(msg->width);
  view.height = static_cast<int>(msg->height);
  view.channels = enc::numChannels(msg->encoding);
  view.step = msg->step;
  view.owner = keepAlive(msg);
  return view;
}

void checkDepthEncoding(const sensor_msgs::Image& msg) {
  if (msg.encoding != enc::TYPE_16UC1 && msg.encoding != enc::MONO16 &&
      msg.encoding != enc::TYPE_32FC1)
    throw core::InvalidInput("depth encoding '" + msg.encoding +
                             "' is not 16UC1 (millimetres) or 32FC1 (metres)");
}

cv::Mat depthToMetres(const sensor_msgs::Image& msg, double metres_per_unit_16u) {
  checkDepthEncoding(msg);
  const cv::Mat view = imageView(msg);
  return images::depthToMetres(view, view.type() == CV_16UC1 ? metres_per_unit_16u : 1.0);
}

core::CameraPose poseFromMsg(const geometry_msgs::Pose& pose) {
  core::CameraPose p;
  p.position = {pose.position.x, pose.position.y, pose.position.z};
  p.orientation = Eigen::Quaterniond(pose.orientation.w, pose.orientation.x, pose.orientation.y,
                                     pose.orientation.z);
  return p;
}

core::CameraPose poseFromTransform(const geometry_msgs::Transform& t) {
  core::CameraPose p;
  p.position = {t.translation.x, t.translation.y, t.translation.z};
  p.orientation = Eigen::Quaterniond(t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z);
  return p;
}

geometry_msgs::Pose poseToMsg(const core::CameraPose& pose) {
  geometry_msgs::Pose m;
  m.position.x = pose.position.x();
  m.position.y = pose.position.y();
  m.position.z = pose.position.z();
  m.orientation.w = pose.orientation.w();
  m.orientation.x = pose.orientation.x();
  m.orientation.y = pose.orientation.y();
  m.orientation.z = pose.orientation.z();
  return m;
}

geometry_msgs::Transform transformToMsg(const core::CameraPose& pose) {
  geometry_msgs::Transform m;
  m.translation.x = pose.position.x();
  m.translation.y = pose.position.y();
  m.translation.z = pose.position.z();
  m.rotation.w = pose.orientation.w();
  m.rotation.x = pose.orientation.x();
  m.rotation.y = pose.orientation.y();
  m.rotation.z = pose.orientation.z();
  return m;
}

std::string keyframeImageName(double stamp) { return core::defaultImageName(stamp); }

namespace {

view_selection::ViewSelection selectionHeader(const core::SelectionOutput& snapshot,
                                              const std::string& world_frame) {
  const core::ChunkedSelection& selection = snapshot.selection;
  view_selection::ViewSelection m;
  m.header.frame_id = world_frame;
  if (snapshot.size() > 0) m.header.stamp = ros::Time(snapshot.keyframes.back().stamp);
  m.completion = core::toString(snapshot.config.completion);
  m.k = snapshot.config.k;
  m.start_view = selection.start_view;
  const auto [s, s_first] = selection.initialPair();
  if (s >= 0 && s_first >= 0) m.initial_pair = {s, s_first};
  m.finite_entries = static_cast<uint32_t>(snapshot.table.finiteCount());
  m.total_keyframes = static_cast<uint32_t>(snapshot.size());
  return m;
}

}  // namespace

view_selection::ViewPair pairToMsg(core::ViewId a, core::ViewId b) {
  view_selection::ViewPair p;
  p.first = a;
  p.second = b;
  return p;
}

view_selection::KeyframeInfo keyframeToMsg(const core::SelectionOutput& snapshot,
                                           core::ViewId view) {
  const core::KeyframeSummary& kf = snapshot.keyframes[static_cast<size_t>(view)];
  view_selection::KeyframeInfo info;
  info.id = view;
  info.stamp = ros::Time(kf.stamp);
  info.image_name = snapshot.imageName(static_cast<size_t>(view));
  info.pose = poseToMsg(kf.pose);
  info.num_points = static_cast<int32_t>(kf.num_points);
  info.revisit_of = kf.revisit_of;
  info.intrinsics = {kf.intrinsics.fx, kf.intrinsics.fy, kf.intrinsics.cx, kf.intrinsics.cy};
  info.width = static_cast<uint32_t>(std::max(0, kf.intrinsics.width));
  info.height = static_cast<uint32_t>(std::max(0, kf.intrinsics.height));
  return info;
}

view_selection::NextViewSet nextViewSetToMsg(const core::SelectionOutput& snapshot,
                                             core::ViewId view) {
  const core::ChunkedSelection& selection = snapshot.selection;
  const core::ErrorResistanceTable& e = snapshot.table;
  const auto i = static_cast<size_t>(view);
  view_selection::NextViewSet set;
  set.view = view;
  if (i >= selection.next_views.size()) return set;
  for (const core::ViewId j : selection.next_views[i]) {
    set.next_views.push_back(j);
    set.error_resistance.push_back(e.at(view, j));
  }
  if (i >= selection.final_next_views.size()) return set;
  const auto& fin = selection.final_next_views[i];
  for (size_t q = selection.next_views[i].size(); q < fin.size(); ++q) {
    set.completed_views.push_back(fin[q]);
    set.completed_error_resistance.push_back(e.at(view, fin[q]));
  }
  return set;
}

view_selection::ViewSelection selectionToMsg(const core::SelectionOutput& snapshot,
                                             const std::string& world_frame) {
  const core::ChunkedSelection& selection = snapshot.selection;
  view_selection::ViewSelection m = selectionHeader(snapshot, world_frame);
  const size_t n = snapshot.size();
  m.keyframes.resize(n);
  for (size_t i = 0; i < n; ++i) m.keyframes[i] = keyframeToMsg(snapshot, static_cast<core::ViewId>(i));
  m.next_view_sets.resize(selection.next_views.size());
  for (size_t i = 0; i < selection.next_views.size(); ++i)
    m.next_view_sets[i] = nextViewSetToMsg(snapshot, static_cast<core::ViewId>(i));
  m.order.assign(selection.order.begin(), selection.order.end());
  for (const auto& c : selection.completed) {
    view_selection::CompletedView cv;
    cv.view = c.view;
    cv.added_to = c.added_to;
    m.completed.push_back(cv);
  }
  m.isolated.assign(selection.isolated.begin(), selection.isolated.end());
  for (const auto& [a, b] : selection.pairs) m.pairs.push_back(pairToMsg(a, b));
  return m;
}

view_selection::ViewSelection selectionUpdateToMsg(const core::SelectionOutput& snapshot,
                                                   const std::string& world_frame,
                                                   const std::vector<core::ViewId>& views) {
  view_selection::ViewSelection m = selectionHeader(snapshot, world_frame);
  m.partial = true;
  m.keyframes.reserve(views.size());
  m.next_view_sets.reserve(views.size());
  for (const core::ViewId v : views) {
    m.keyframes.push_back(keyframeToMsg(snapshot, v));
    m.next_view_sets.push_back(nextViewSetToMsg(snapshot, v));
  }
  return m;
}

}  // namespace view_selection::ros_node
