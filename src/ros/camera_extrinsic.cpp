#include "view_selection/ros/camera_extrinsic.h"

#include "view_selection/ros/conversions.h"

#include <tf2/exceptions.h>

namespace view_selection::ros_node {

CameraExtrinsic::CameraExtrinsic(ros::NodeHandle nh) : listener_(buffer_, nh, true) {}

std::optional<core::CameraPose> CameraExtrinsic::lookup(const std::string& body,
                                                        const std::string& camera, double timeout,
                                                        std::string* error) {
  if (body.empty() || body == camera) return core::CameraPose{};
  const auto key = std::make_pair(body, camera);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = known_.find(key);
    if (it != known_.end()) return it->second;
  }
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout);
  std::string why;
  while (!buffer_.canTransform(body, camera, ros::Time(0), &why)) {
    if (stopping_ || ros::WallTime::now() >= deadline || !ros::ok()) {
      if (error) *error = why;
      return std::nullopt;
    }
    ros::WallDuration(kPollPeriod).sleep();
  }
  try {
    const core::CameraPose pose =
        poseFromTransform(buffer_.lookupTransform(body, camera, ros::Time(0)).transform);
    if (!pose.isValid()) {
      if (error) *error = "the transform is not finite";
      return std::nullopt;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    known_[key] = pose;
    ROS_INFO_STREAM("view_selection: camera extrinsic " << body << " <- " << camera << ": t = ("
                                                        << pose.position.transpose() << ")");
    return pose;
  } catch (const tf2::TransformException& e) {
    if (error) *error = e.what();
    return std::nullopt;
  }
}

}  // namespace view_selection::ros_node
