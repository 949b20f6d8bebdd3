// Loop-closure corrections from a nav_msgs/Path on `path` (VINS' pose_graph_path, RTAB-Map's
// mapPath: the whole corrected trajectory, republished after every loop closure). Its poses are
// of the same body frame as the topic pose source (~body_frame; else the optical frame) in
// ~world_frame; each keyframe takes the path's pose nearest its stamp within
// ~correction_stamp_tolerance, and keyframes that moved more than the thresholds are corrected
// (rows and columns recomputed; the selection is republished). Its own thread: the extrinsic
// lookup may wait.
#pragma once

#include "view_selection/ros/camera_extrinsic.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_worker.h"
#include "view_selection/ros/node_config.h"

#include <nav_msgs/Path.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <memory>

namespace view_selection::ros_node {

class PathCorrections {
 public:
  /// Subscribes to `path` on `nh` when ~use_path_corrections is set; else does nothing.
  PathCorrections(const NodeConfig& config, ros::NodeHandle nh, KeyframeWorker& worker,
                  InputStatistics& statistics);
  ~PathCorrections();

 private:
  static constexpr uint32_t kQueue = 2;  ///< each path replaces the last: keep few

  void onPath(const nav_msgs::PathConstPtr& path);

  const NodeConfig& config_;
  ros::NodeHandle nh_;
  KeyframeWorker& worker_;
  InputStatistics& statistics_;
  std::unique_ptr<CameraExtrinsic> extrinsic_;
  ros::CallbackQueue queue_;
  ros::Subscriber subscriber_;
  std::unique_ptr<ros::AsyncSpinner> spinner_;
};

}  // namespace view_selection::ros_node
