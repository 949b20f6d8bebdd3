// ~keyframe_policy external: the SLAM system decides which frames are keyframes. Its keyframe
// stamps arrive on `keyframes` (nav_msgs/Path, e.g. ORB-SLAM's or VINS' keyframe trajectory: the
// stamps of its poses); a frame is a keyframe when a stamp lies within ~keyframe_stamp_tolerance
// of its own, and is not once a later stamp came (the system decides in order). A frame waits at
// most ~keyframe_verdict_timeout for that; one that never gets a verdict is dropped and counted.
#pragma once

#include "view_selection/ros/node_config.h"

#include <nav_msgs/Path.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <condition_variable>
#include <mutex>
#include <set>

namespace view_selection::ros_node {

class KeyframeVerdicts {
 public:
  enum class Verdict { kKeyframe, kNotKeyframe, kUnknown };

  /// Subscribes to `keyframes` when ~keyframe_policy is external; else does nothing.
  KeyframeVerdicts(const NodeConfig& config, ros::NodeHandle nh);
  ~KeyframeVerdicts();
  bool active() const { return active_; }
  /// The verdict for a frame at `stamp`, waiting at most ~keyframe_verdict_timeout [s, wall].
  Verdict wait(const ros::Time& stamp);
  /// The verdict from the stamps so far, without waiting.
  Verdict now(const ros::Time& stamp) const;
  /// Forgets every stamp (~reset); a frame waiting for its verdict gives up (kUnknown).
  void reset();
  /// A time jump to `stamp` started a new session: the stamps from `stamp` on (less the
  /// tolerance) are of the old timeline and are forgotten (earlier ones cannot decide a frame
  /// of the new session), unless a path already started a new timeline since the last call (its
  /// newest stamp more than ~time_jump_threshold before the newest known: then the stamps are
  /// that path's). A frame waiting for its verdict gives up.
  void newTimeline(const ros::Time& stamp);
  void stop();
  std::string describe() const;

 private:
  static constexpr size_t kMaxStamps = 100000;

  Verdict verdictLocked(const ros::Time& stamp) const;
  void onPath(const nav_msgs::PathConstPtr& path);

  const NodeConfig& config_;
  bool active_ = false;
  ros::NodeHandle nh_;
  mutable std::mutex mutex_;
  std::condition_variable arrived_;
  std::set<ros::Time> stamps_;
  bool timeline_started_ = false;  // by a path since the last newTimeline()
  uint64_t resets_ = 0;            // reset() and newTimeline() calls: waits end
  bool stopping_ = false;
  ros::CallbackQueue queue_;
  ros::Subscriber subscriber_;
  std::unique_ptr<ros::AsyncSpinner> spinner_;
};

}  // namespace view_selection::ros_node
