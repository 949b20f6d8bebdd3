// Loop-closure corrections from a nav_msgs/Path on `path` (VINS' pose_graph_path, RTAB-Map's
// mapPath: the whole corrected trajectory, republished after every loop closure, with a pose for
// each of the SLAM system's own keyframes only). Its poses are of the same body frame as the
// topic pose source (~body_frame; else the optical frame) in ~world_frame. The correction at each
// path pose is that pose composed with the inverse of the pose the node had at its stamp (the
// pose source's history, interpolated within ~correction_max_source_gap); every keyframe of the
// node takes the correction interpolated at its stamp (the nearest outside the path), and those
// that moved more than the thresholds are corrected (rows and columns recomputed; the selection
// is republished). Its own thread: the extrinsic lookup may wait.
#pragma once

#include "view_selection/ros/camera_extrinsic.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_worker.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/pose_provider.h"

#include <nav_msgs/Path.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <memory>

namespace view_selection::ros_node {

class PathCorrections {
 public:
  /// Subscribes to `path` on `nh` when ~use_path_corrections is set; else does nothing.
  PathCorrections(const NodeConfig& config, ros::NodeHandle nh, KeyframeWorker& worker,
                  const PoseProvider& poses, InputStatistics& statistics);
  ~PathCorrections();

 private:
  static constexpr uint32_t kQueue = 2;  ///< each path replaces the last: keep few
  /// [s] A path with no pose among the node's frames, ending at most this long before the first
  /// one or starting at most this long after the last one looked up, is nothing to correct yet
  /// (a SLAM system's first paths); further off it is a wrong one (bad_path).
  static constexpr double kNotYetSeconds = 5.0;

  void onPath(const nav_msgs::PathConstPtr& path);

  const NodeConfig& config_;
  ros::NodeHandle nh_;
  KeyframeWorker& worker_;
  const PoseProvider& poses_;
  InputStatistics& statistics_;
  std::unique_ptr<CameraExtrinsic> extrinsic_;
  ros::CallbackQueue queue_;
  ros::Subscriber subscriber_;
  std::unique_ptr<ros::AsyncSpinner> spinner_;
};

}  // namespace view_selection::ros_node
