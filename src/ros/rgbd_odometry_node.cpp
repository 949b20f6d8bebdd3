// rgbd_odometry: the odometry stand-in (OpenCV's RGB-D odometry) on a node of its own.
#include "view_selection/ros/node_main.h"
#include "view_selection/ros/rgbd_odometry_ros.h"

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

}  // namespace

int main(int argc, char** argv) {
  using namespace view_selection::ros_node;
  return runNode<RgbdOdometryRos>(argc, argv, "rgbd_odometry", "rgbd_odometry", kUsage);
}
