// rgbd_odometry: the odometry stand-in (OpenCV's RGB-D odometry) on a node of its own.
#include "view_selection/ros/rgbd_odometry_ros.h"

#include <ros/ros.h>

#include <memory>

int main(int argc, char** argv) {
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
