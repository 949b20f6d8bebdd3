#pragma once
// The main() of a node that is one class: --help answered before ros::init (no master needed),
// the class constructed on the node's handles, a constructor that throws logged as fatal.

#include <ros/ros.h>

#include <cstdio>
#include <cstring>
#include <exception>
#include <memory>

namespace view_selection::ros_node {

inline bool asksForHelp(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) return true;
  return false;
}

/// `node_name`: ros::init's default name; `program`: how fatal errors name the executable.
template <typename Node>
int runNode(int argc, char** argv, const char* node_name, const char* program, const char* usage) {
  if (asksForHelp(argc, argv)) {
    std::fputs(usage, stdout);
    return 0;
  }
  ros::init(argc, argv, node_name);
  // Handles outlive the constructor: if it throws, ROS (and its logging) must still be up.
  ros::NodeHandle nh, private_nh("~");
  std::unique_ptr<Node> node;
  try {
    node = std::make_unique<Node>(nh, private_nh);
  } catch (const std::exception& e) {
    ROS_FATAL("%s: %s", program, e.what());
    return 1;
  }
  ros::spin();
  node.reset();
  return 0;
}

}  // namespace view_selection::ros_node
