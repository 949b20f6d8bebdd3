// The message conversions of the node: Image (as colour and as depth), CameraInfo, PointCloud2
// and poses, every field from the input (sizes, steps, encodings, offsets, NaNs).
#include "fuzz_target.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/ros/conversions.h"

#include <sensor_msgs/image_encodings.h>
#include <boost/make_shared.hpp>

#include <cmath>
#include <iterator>

using namespace view_selection;
namespace enc = sensor_msgs::image_encodings;

namespace {

const std::string kEncodings[] = {
    enc::RGB8,         enc::BGR8,       enc::RGBA8,      enc::BGRA8,     enc::MONO8,
    enc::MONO16,       enc::TYPE_16UC1, enc::TYPE_32FC1, enc::TYPE_8UC3, enc::BAYER_RGGB8,
    enc::BAYER_GRBG16, enc::YUV422,     enc::TYPE_64FC1, enc::TYPE_8SC1, "not_an_encoding"};

std::string encoding(fuzz::Bytes& in) {
  const uint32_t pick = in.below(20);
  return pick < std::size(kEncodings) ? kEncodings[pick] : in.text(16);
}

void image(fuzz::Bytes& in) {
  auto msg = boost::make_shared<sensor_msgs::Image>();
  msg->width = in.below(2048);
  msg->height = in.below(2048);
  msg->encoding = encoding(in);
  msg->is_bigendian = in.take<uint8_t>() % 2;
  msg->step = in.take<uint8_t>() < 200 ? msg->width * static_cast<uint32_t>(in.below(17))
                                       : in.take<uint32_t>();
  msg->data = in.bytes(in.below(1 << 20));
  const bool as_depth = in.take<uint8_t>() % 2;
  try {
    ros_node::checkImageMessage(*msg, as_depth ? "depth" : "image");
    if (as_depth) {
      ros_node::checkDepthEncoding(*msg);
      const cv::Mat m = ros_node::depthToMetres(*msg, 0.001);
      if (m.rows != static_cast<int>(msg->height) || m.cols != static_cast<int>(msg->width))
        fuzz::broken("depthToMetres changed the size");
    } else {
      const core::ColourImage c = ros_node::colourImageForCore(msg);
      const core::ColourImage b = ros_node::borrowedImageView(msg);
      (void)b;
      if (c.width != static_cast<int>(msg->width)) fuzz::broken("colour image changed size");
      volatile uint8_t last = c.row(c.height - 1)[c.width * c.channels - 1];  // must be readable
      (void)last;
    }
  } catch (const core::Error&) {
  }
}

void cameraInfo(fuzz::Bytes& in) {
  sensor_msgs::CameraInfo info;
  for (double& k : info.K) k = in.take<double>();
  info.width = in.take<uint32_t>();
  info.height = in.take<uint32_t>();
  try {
    const core::PinholeIntrinsics k = ros_node::intrinsicsFromCameraInfo(info);
    if (!k.isValid()) fuzz::broken("intrinsicsFromCameraInfo accepted invalid intrinsics");
  } catch (const core::Error&) {
  }
}

void cloud(fuzz::Bytes& in) {
  sensor_msgs::PointCloud2 c;
  const uint32_t fields = in.below(6);
  for (uint32_t f = 0; f < fields; ++f) {
    sensor_msgs::PointField field;
    const uint32_t name = in.below(5);
    field.name = name < 3 ? std::string(1, "xyz"[name]) : name == 3 ? "rgb" : in.text(4);
    field.offset = in.take<uint8_t>() < 240 ? in.below(32) : in.take<uint32_t>();
    field.datatype = static_cast<uint8_t>(
        in.take<uint8_t>() < 200 ? uint32_t{sensor_msgs::PointField::FLOAT32} : in.below(9));
    field.count = in.below(3);
    c.fields.push_back(field);
  }
  c.width = in.take<uint8_t>() < 200 ? in.below(300) : in.take<uint32_t>();
  c.height = in.take<uint8_t>() < 200 ? in.below(4) : in.take<uint32_t>();
  c.point_step = in.take<uint8_t>() < 200 ? in.below(40) : in.take<uint32_t>();
  c.row_step = in.take<uint8_t>() < 200 ? c.point_step * c.width : in.take<uint32_t>();
  c.is_bigendian = in.take<uint8_t>() % 8 == 0;
  c.data = in.rest();
  try {
    const Eigen::Matrix3Xd points = ros_node::mapPointsFromCloud(c);
    if (!points.allFinite()) fuzz::broken("mapPointsFromCloud returned non-finite points");
    if (static_cast<uint64_t>(points.cols()) > static_cast<uint64_t>(c.width) * c.height)
      fuzz::broken("more points than the cloud has");
  } catch (const core::Error&) {
  }
}

void pose(fuzz::Bytes& in) {
  geometry_msgs::Pose p;
  p.position.x = in.take<double>();
  p.position.y = in.take<double>();
  p.position.z = in.take<double>();
  p.orientation.x = in.take<double>();
  p.orientation.y = in.take<double>();
  p.orientation.z = in.take<double>();
  p.orientation.w = in.take<double>();
  const core::CameraPose a = ros_node::poseFromMsg(p);
  const geometry_msgs::Pose back = ros_node::poseToMsg(a);
  geometry_msgs::Transform t = ros_node::transformToMsg(a);
  const core::CameraPose b = ros_node::poseFromTransform(t);
  if (a.isValid()) {
    if (!b.isValid()) fuzz::broken("a valid pose became invalid through a transform");
    if (!std::isfinite(back.position.x)) fuzz::broken("a valid pose lost its position");
    (void)a.rotation();
  }
}

}  // namespace

VIEW_SELECTION_FUZZ_TARGET(messages) {
  fuzz::Bytes in(data, size);
  switch (in.below(4)) {
    case 0:
      return image(in);
    case 1:
      return cameraInfo(in);
    case 2:
      return cloud(in);
    default:
      return pose(in);
  }
}
