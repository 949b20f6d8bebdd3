#include "view_selection/ros/path_corrections.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/pose_interpolation.h"
#include "view_selection/ros/conversions.h"

#include <algorithm>

namespace view_selection::ros_node {

PathCorrections::PathCorrections(const NodeConfig& config, ros::NodeHandle nh,
                                 KeyframeWorker& worker, const PoseProvider& poses,
                                 InputStatistics& statistics)
    : config_(config), nh_(nh), worker_(worker), poses_(poses), statistics_(statistics) {
  if (!config_.use_path_corrections) return;
  extrinsic_ = std::make_unique<CameraExtrinsic>(nh);
  ros::SubscribeOptions options = ros::SubscribeOptions::create<nav_msgs::Path>(
      "path", kQueue, [this](const nav_msgs::PathConstPtr& p) { onPath(p); }, ros::VoidPtr(),
      &queue_);
  subscriber_ = nh_.subscribe(options);
  spinner_ = std::make_unique<ros::AsyncSpinner>(1, &queue_);
  spinner_->start();
}

PathCorrections::~PathCorrections() {
  if (extrinsic_) extrinsic_->stop();
  if (spinner_) spinner_->stop();
  subscriber_.shutdown();
}

void PathCorrections::onPath(const nav_msgs::PathConstPtr& path) {
  const ros::Time stamp = path->header.stamp;
  auto reject = [&](const std::string& why) {
    statistics_.dropInput("bad_path", "ignored the path on '" + nh_.resolveName("path") + "': " + why,
                     stamp);
  };
  const std::string camera =
      config_.camera_frame.empty() ? worker_.cameraFrame() : config_.camera_frame;
  if (camera.empty()) return;  // no frame yet: nothing to correct
  const std::string body = config_.body_frame.empty() ? camera : config_.body_frame;
  std::string error;
  const std::optional<core::CameraPose> extrinsic =
      extrinsic_->lookup(body, camera, config_.pose_timeout, &error);
  if (!extrinsic)
    return reject("tf has no transform " + body + " <- " + camera + " (~body_frame): " + error);
  std::vector<core::TimedPose> trajectory;
  trajectory.reserve(path->poses.size());
  for (const geometry_msgs::PoseStamped& p : path->poses) {
    const std::string frame =
        normaliseFrameId(p.header.frame_id.empty() ? path->header.frame_id : p.header.frame_id);
    if (frame != config_.world_frame)
      return reject("a pose is in frame '" + frame + "', not ~world_frame '" + config_.world_frame +
                    "'");
    const core::CameraPose pose = poseFromMsg(p.pose);
    if (!pose.isValid()) return reject("a pose is not finite or not a rotation");
    // Relative to the path's first stamp would be finer, but keyframe stamps are seconds too.
    trajectory.push_back({p.header.stamp.toSec(), core::composePoses(pose, *extrinsic)});
  }
  std::stable_sort(
      trajectory.begin(), trajectory.end(),
      [](const core::TimedPose& a, const core::TimedPose& b) { return a.stamp < b.stamp; });
  // What the node had at each path stamp: the correction there is path pose * that^-1.
  const double gap = config_.corrections.max_source_gap;
  std::vector<std::optional<core::CameraPose>> sources;
  sources.reserve(trajectory.size());
  for (const core::TimedPose& p : trajectory) sources.push_back(poses_.historyAt(p.stamp, gap));
  const std::vector<core::TimedPose> corrections = core::pathCorrections(trajectory, sources);
  // A SLAM system publishes its path from its first keyframes on (VINS' loop_fusion with each
  // one it adds): its first paths may end just before the node's first frame, or lie just beyond
  // the frames looked up so far. With no pose among the node's frames and its stamps next to
  // them, such a path is nothing to correct yet, not a wrong one; far from them it is wrong.
  if (corrections.empty() && !trajectory.empty()) {
    const std::optional<std::pair<double, double>> span = poses_.historySpan();
    const bool overlaps = span && std::any_of(trajectory.begin(), trajectory.end(),
                                              [&](const core::TimedPose& p) {
                                                return p.stamp >= span->first &&
                                                       p.stamp <= span->second;
                                              });
    const bool next_to = !span || (trajectory.back().stamp >= span->first - kNotYetSeconds &&
                                   trajectory.front().stamp <= span->second + kNotYetSeconds);
    if (!overlaps && next_to) {
      ROS_DEBUG_STREAM("view_selection: a path of " << trajectory.size()
                                                    << " poses, none among the node's frames yet");
      return;
    }
    return reject("none of its " + std::to_string(trajectory.size()) +
                  " poses lies among the node's own poses (within " + std::to_string(gap) +
                  " s, ~correction_max_source_gap), so no correction is known: a path of another "
                  "session, or of stamps the node never had frames at");
  }
  try {
    const size_t moved = worker_.correctPoses(
        corrections, [&](double stamp) { return poses_.historyAt(stamp, 0.0); },
        config_.corrections);
    statistics_.pathApplied(moved);
    ROS_DEBUG_STREAM("view_selection: path of " << trajectory.size() << " poses ("
                                                << corrections.size() << " with a correction), "
                                                << moved << " keyframes corrected");
  } catch (const core::Error& e) {
    reject(e.what());
  }
}

}  // namespace view_selection::ros_node
