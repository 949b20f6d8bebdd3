// rgbd_odometry: the odometry stand-in (OpenCV's RGB-D odometry) on a node of its own.
#include "view_selection/ros/rgbd_odometry_ros.h"

#include <ros/ros.h>

#include <cstdio>
#include <cstring>
#include <memory>

namespace {

constexpr const char* kUsage =
    R"(usage: rosrun view_selection rgbd_odometry image:=TOPIC camera_info:=TOPIC depth:=TOPIC [_param:=value ...]

Frame-to-frame (or frame-to-keyframe) RGB-D odometry with OpenCV's cv::rgbd: a pose source for a
bag that has images and depth but no poses, and a stand-in for a SLAM front end. It drifts and it
does not close loops (docs/live.md, "The odometry stand-in").

Subscribes   image, camera_info, depth (16UC1 mm or 32FC1 m)
Publishes    ~odometry (nav_msgs/Odometry) and tf ~odom_frame -> the camera frame
Parameters   ~method (rgbd|icp|rgbd_icp), ~reference (frame|keyframe), ~odom_frame (odom),
             ~camera_frame (the images' frame_id), ~publish_tf, ~max_width, ...
With the view selection node:
  roslaunch view_selection tum_replay.launch bag:=BAG odometry:=true
)";

bool asksForHelp(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) return true;
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  if (asksForHelp(argc, argv)) {  // before ros::init: no master needed
    std::fputs(kUsage, stdout);
    return 0;
  }
  ros::init(argc, argv, "rgbd_odometry");
  ros::NodeHandle nh, private_nh("~");
  std::unique_ptr<view_selection::ros_node::RgbdOdometryRos> node;
  try {
    node = std::make_unique<view_selection::ros_node::RgbdOdometryRos>(nh, private_nh);
  } catch (const std::exception& e) {
    ROS_FATAL("rgbd_odometry: %s", e.what());
    return 1;
  }
  ros::spin();
  node.reset();
  return 0;
}
