// The fixed transform from a body frame (what a SLAM system publishes poses of: ORB-SLAM2's
// camera_link, VINS' body, RTAB-Map's base_link) to the camera's optical frame, looked up once
// from tf (the latest transform; /tf_static or a static publisher on /tf) and kept.
#pragma once

#include "view_selection/core/types.h"

#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <map>
#include <mutex>
#include <optional>
#include <string>

namespace view_selection::ros_node {

class CameraExtrinsic {
 public:
  explicit CameraExtrinsic(ros::NodeHandle nh);
  /// The optical frame's pose in the body frame (body <- camera): identity when they are the
  /// same frame; else from tf, waiting at most `timeout` [s, wall] the first time. nullopt (and
  /// `error`) when tf has no such transform yet; a later call tries again.
  std::optional<core::CameraPose> lookup(const std::string& body, const std::string& camera,
                                         double timeout, std::string* error);
  /// Makes waiting lookups return at once (shutdown).
  void stop() { stopping_ = true; }

 private:
  static constexpr double kPollPeriod = 0.005;  ///< [s, wall] between canTransform checks

  std::atomic<bool> stopping_{false};
  std::mutex mutex_;
  std::map<std::pair<std::string, std::string>, core::CameraPose> known_;
  tf2_ros::Buffer buffer_;
  tf2_ros::TransformListener listener_;  // spins a thread of its own
};

}  // namespace view_selection::ros_node
