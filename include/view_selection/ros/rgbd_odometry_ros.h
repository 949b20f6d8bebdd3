// rgbd_odometry: the odometry stand-in as a ROS node (issue 29). It takes image, depth and
// camera_info (no pose input), tracks with OpenCV's RGB-D odometry (odometry/rgbd_odometry) and
// publishes what a SLAM front end without loop closure publishes: nav_msgs/Odometry on ~odometry
// and tf ~odom_frame -> the camera's optical frame, at each image's stamp. It drifts and it
// never closes a loop. A frame it cannot track (a blank image, depth all zeros, a motion it
// cannot explain) gets no pose, a throttled warning that says why, and a count (/diagnostics).
//
// Threads: roscpp's spinner pairs each image with the depth nearest its stamp (and the newest
// camera_info) and hands the pair to the tracking thread through a one-frame mailbox: a frame
// that arrives while the tracker is busy replaces the waiting one (counted: `skipped`), as a
// real front end that cannot keep up skips frames.
#pragma once

#include "view_selection/odometry/rgbd_odometry.h"

#include <diagnostic_updater/diagnostic_updater.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <tf2_ros/transform_broadcaster.h>

#include <condition_variable>
#include <deque>
#include <mutex>
#include <string>
#include <thread>

namespace view_selection::ros_node {

struct RgbdOdometryRosConfig {
  odometry::OdometryConfig odometry;
  std::string odom_frame = "odom";  ///< the frame its poses are in (REP 105's odom)
  std::string camera_frame;         ///< child frame; "" = the images' frame_id
  bool publish_tf = true;
  double max_stamp_difference = 0.02;  ///< [s] an image and its depth must be this close
  double depth_metres_per_unit = 0.001;  ///< 16UC1 depth: millimetres
  double time_jump = 1.0;  ///< [s] an image this much before the newest starts a new session
};

/// Reads the private parameters (~reference, ~method, ~odom_frame, ...); throws
/// core::InvalidArgument for a bad one.
RgbdOdometryRosConfig loadRgbdOdometryConfig(const ros::NodeHandle& private_nh);

class RgbdOdometryRos {
 public:
  RgbdOdometryRos(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~RgbdOdometryRos();

 private:
  struct Pending {
    sensor_msgs::ImageConstPtr image, depth;
    sensor_msgs::CameraInfoConstPtr info;
  };
  void onImage(const sensor_msgs::ImageConstPtr& msg);
  void onDepth(const sensor_msgs::ImageConstPtr& msg);
  void onInfo(const sensor_msgs::CameraInfoConstPtr& msg);
  void pair();  ///< under lock_: images waiting that can be paired now go to the mailbox
  void run();   ///< the tracking thread
  void track(const Pending& frame);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  RgbdOdometryRosConfig config_;
  ros::NodeHandle nh_, private_nh_;
  ros::Subscriber image_sub_, depth_sub_, info_sub_;
  ros::Publisher odometry_pub_;
  tf2_ros::TransformBroadcaster tf_;
  diagnostic_updater::Updater diagnostics_;
  ros::WallTimer diagnostics_timer_;

  std::mutex lock_;
  std::condition_variable wake_;
  std::deque<sensor_msgs::ImageConstPtr> images_, depths_;
  sensor_msgs::CameraInfoConstPtr info_;
  Pending mailbox_;
  bool has_mail_ = false, stopping_ = false;
  ros::Time newest_;
  // counts (under lock_)
  uint64_t images_received_ = 0, paired_ = 0, unpaired_ = 0, skipped_ = 0, bad_input_ = 0, sessions_ = 1;
  uint64_t tracked_ = 0, lost_ = 0, restarts_ = 0, lost_in_period_ = 0;
  std::string last_lost_, last_error_;
  double seconds_ = 0.0;

  odometry::RgbdOdometryTracker tracker_;  // the tracking thread's alone
  bool reset_tracker_ = false;
  std::thread thread_;
};

}  // namespace view_selection::ros_node
