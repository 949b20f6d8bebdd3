// Where a frame's camera pose comes from: tf (world_frame <- camera frame at the image stamp) or
// a topic of the messages SLAM systems publish (geometry_msgs/PoseStamped, nav_msgs/Odometry,
// geometry_msgs/PoseWithCovarianceStamped), interpolated at the image stamp, of a body frame
// whose fixed transform to the optical frame comes from tf once. Each receives poses on a thread
// of its own, so poses keep arriving while the worker waits for one.
#pragma once

#include "view_selection/core/pose_history.h"
#include "view_selection/core/pose_interpolation.h"
#include "view_selection/core/types.h"
#include "view_selection/ros/camera_extrinsic.h"
#include "view_selection/ros/node_config.h"

#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <nav_msgs/Odometry.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <tf2_msgs/TFMessage.h>
#include <tf2_ros/buffer.h>

#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

namespace view_selection::ros_node {

/// The answer to one lookup: a pose, or the drop reason ("no_pose", "bad_pose") and why.
struct PoseLookup {
  std::optional<core::CameraPose> pose;
  /// With NodeConfig::correctionFrame() (tf, ~odom_frame): the pose in that frame, which path
  /// corrections are measured against (the history keeps it instead of `pose`).
  std::optional<core::CameraPose> uncorrected;
  std::string reason;
  std::string message;
};

class PoseProvider {
 public:
  virtual ~PoseProvider() = default;
  /// The optical frame's pose at `stamp`; `image_frame` is the image's (normalised) frame_id.
  /// Waits at most ~pose_timeout (wall) for it, less once stop() was called.
  virtual PoseLookup lookup(const std::string& image_frame, const ros::Time& stamp) = 0;
  /// Forgets poses received so far, and the history (~reset).
  virtual void reset();
  /// A time jump to `stamp` started a new session (before its first frame is looked up): the
  /// poses received belong to the old timeline and are forgotten when they reach more than
  /// ~time_jump_threshold beyond `stamp`, unless the pose input already started a new timeline
  /// of its own since the last call (its stamps went back by more than the threshold: then what
  /// it holds is the new timeline's).
  virtual void newTimeline(const ros::Time& /*stamp*/) {}
  /// Forgets the history (a new session; called by the worker, which records it).
  void clearHistory();
  /// The pose a lookup returned at `stamp` (its `uncorrected` pose, when it has one), or
  /// interpolated between the two around it when each is within `max_gap` [s]: the pose source's
  /// history over the session, for loop-closure corrections (core::PoseHistory). Thread-safe.
  std::optional<core::CameraPose> historyAt(double stamp, double max_gap) const;
  /// The stamps of the history's first and last poses (the frames looked up), if any.
  std::optional<std::pair<double, double>> historySpan() const;
  /// Wakes every waiting lookup and makes later ones return at once (shutdown).
  virtual void stop() = 0;
  /// For the start-up log line, e.g. "tf (world <- image frame_id)".
  virtual std::string describe() const = 0;

 protected:
  /// Lookups keep what they return, by stamp.
  void record(const ros::Time& stamp, const core::CameraPose& pose);

 private:
  mutable std::mutex history_mutex_;
  core::PoseHistory history_;
};

/// tf2: lookupTransform(world_frame, camera frame, stamp), camera frame = ~camera_frame or the
/// image's frame_id; with NodeConfig::correctionFrame() also (that frame, camera frame, stamp),
/// the pose corrections are measured against (RTAB-Map: odom <- camera, which its loop closures
/// do not change, where map <- camera takes them through map -> odom). /tf and /tf_static go into
/// the buffer as tf2_ros::TransformListener puts them (on a thread of their own; the buffer cleared
/// when ROS time goes back), and besides: a transform stamped more than ~time_jump_threshold before
/// the newest of its child frame starts a new timeline (the buffer is cleared first), also without
/// simulated time (a bag played again without --clock, whose transforms tf2 would otherwise mix
/// with the old ones or refuse as too old).
class TfPoseProvider : public PoseProvider {
 public:
  TfPoseProvider(const NodeConfig& config, ros::NodeHandle nh);
  ~TfPoseProvider() override;
  PoseLookup lookup(const std::string& image_frame, const ros::Time& stamp) override;
  void newTimeline(const ros::Time& stamp) override;
  void stop() override { stopping_ = true; }
  std::string describe() const override;

 private:
  static constexpr double kPollPeriod = 0.002;   ///< [s, wall] between canTransform checks
  static constexpr double kCacheSeconds = 30.0;  ///< tf history kept
  static constexpr uint32_t kTfQueue = 100;      ///< as tf2_ros::TransformListener

  void onTf(const ros::MessageEvent<tf2_msgs::TFMessage const>& event, bool is_static);
  /// Under tf_mutex_: a fixed link re-sent on /tf (every message of its child frame the same
  /// transform, as the old static_transform_publisher sent them, stamped ahead by its period:
  /// the TUM benchmark's bags) also holds before its first message, by kFixedLinkBackfill: a
  /// frame stamped just after a replay started (after a restart, `rosbag play -s`) gets its
  /// pose instead of waiting for a transform that can never come.
  void noteLinkLocked(const geometry_msgs::TransformStamped& t, const std::string& authority);
  /// Under tf_mutex_: forgets every transform but the static ones.
  void clearLocked();

  const NodeConfig& config_;
  const std::string correction_frame_;  ///< NodeConfig::correctionFrame()
  std::atomic<bool> stopping_{false};
  tf2_ros::Buffer buffer_;
  std::mutex tf_mutex_;  // the timeline below; held while a transform is added
  std::map<std::string, ros::Time> newest_;  ///< newest stamp by child frame, this timeline
  struct Link {
    geometry_msgs::TransformStamped first;  ///< the earliest message of the child frame
    bool moved = false;                     ///< a message differed from the first
    bool extended = false;                  ///< the first was also added kFixedLinkBackfill earlier
  };
  std::map<std::string, Link> links_;  ///< by child frame, this timeline
  static constexpr double kFixedLinkBackfill = 1.0;  ///< [s]
  bool timeline_started_ = false;            ///< by the transforms since the last newTimeline()
  ros::Time last_update_;                    ///< ROS time of the last /tf message
  ros::CallbackQueue tf_queue_;
  ros::Subscriber tf_sub_, tf_static_sub_;
  ros::AsyncSpinner tf_spinner_;  // last: started once the subscribers exist
};

/// One pose as a topic source received it: of `child_frame` (empty: unknown, see ~body_frame)
/// in `frame`, at `stamp`.
struct ReceivedPose {
  ros::Time stamp;
  std::string frame;
  std::string child_frame;
  core::CameraPose pose;
};

/// Poses on `pose` (PoseStamped, Odometry or PoseWithCovarianceStamped by ~pose_source), in
/// world_frame, of the body frame (~body_frame; else Odometry's child_frame_id; else the optical
/// frame itself). The optical frame's pose at an image stamp: the body poses on either side,
/// each within ~pose_max_time_difference, interpolated (translation linear, rotation slerp), then
/// the fixed body <- optical transform from tf; a pose at the very stamp is taken as it is.
class TopicPoseProvider : public PoseProvider {
 public:
  TopicPoseProvider(const NodeConfig& config, ros::NodeHandle nh);
  ~TopicPoseProvider() override;
  PoseLookup lookup(const std::string& image_frame, const ros::Time& stamp) override;
  void reset() override;
  void newTimeline(const ros::Time& stamp) override;
  void stop() override;
  std::string describe() const override;

  /// Adds `pose` to `poses` (ascending stamp); when it is more than `time_jump` [s] (> 0) before
  /// the newest, the poses before it are of another timeline and are forgotten first (true).
  static bool addPose(std::deque<ReceivedPose>& poses, ReceivedPose pose, double time_jump);

  /// The interpolation step alone, for tests: the body pose at `stamp` from `poses` (ascending
  /// stamp), or the drop reason in `out`.
  static std::optional<ReceivedPose> bodyPoseAt(const std::deque<ReceivedPose>& poses,
                                                const ros::Time& stamp, double max_difference,
                                                PoseLookup& out);

 private:
  static constexpr uint32_t kSubscriberQueue = 1000;  ///< poses buffered by ROS for the spinner
  static constexpr size_t kMaxPoses = 10000;          ///< poses kept at most ...
  static constexpr double kHistorySeconds = 30.0;     ///< ... and for at most this long [s]

  template <typename M>
  void subscribe(ReceivedPose (*convert)(const M&));
  void onPose(ReceivedPose pose);

  const NodeConfig& config_;
  ros::NodeHandle nh_;
  std::mutex mutex_;
  std::condition_variable arrived_;
  std::deque<ReceivedPose> poses_;  // ascending stamp
  bool timeline_started_ = false;   // by the poses since the last newTimeline()
  bool stopping_ = false;
  CameraExtrinsic extrinsic_;
  ros::CallbackQueue queue_;
  ros::Subscriber subscriber_;
  ros::AsyncSpinner spinner_;
};

std::unique_ptr<PoseProvider> makePoseProvider(const NodeConfig& config, ros::NodeHandle nh);

}  // namespace view_selection::ros_node
