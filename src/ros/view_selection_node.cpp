// view_selection_node: the ViewSelectionRos class on a node of its own.
#include "view_selection/core/exceptions.h"
#include "view_selection/ros/view_selection_ros.h"

#include <ros/ros.h>

int main(int argc, char** argv) {
  ros::init(argc, argv, "view_selection_node");
  // Handles outlive the constructor: if it throws, ROS (and its logging) must still be up.
  ros::NodeHandle nh, private_nh("~");
  std::unique_ptr<view_selection::ros_node::ViewSelectionRos> node;
  try {
    node = std::make_unique<view_selection::ros_node::ViewSelectionRos>(nh, private_nh);
  } catch (const std::exception& e) {
    ROS_FATAL("view_selection_node: %s", e.what());
    return 1;
  }
  ros::spin();
  node.reset();
  return 0;
}
