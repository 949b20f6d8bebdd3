#include "view_selection/ros/pose_provider.h"

#include "view_selection/core/parameters.h"
#include "view_selection/ros/conversions.h"
#include "view_selection/ros/input_statistics.h"

#include <tf2/exceptions.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

namespace view_selection::ros_node {

namespace {
std::string seconds(double value) { return core::formatNumber(value) + " s"; }
}  // namespace

void PoseProvider::reset() {
  std::lock_guard<std::mutex> lock(history_mutex_);
  history_.clear();
}

void PoseProvider::clearHistory() {
  std::lock_guard<std::mutex> lock(history_mutex_);
  history_.clear();
}

std::optional<std::pair<double, double>> PoseProvider::historySpan() const {
  std::lock_guard<std::mutex> lock(history_mutex_);
  return history_.span();
}

std::optional<core::CameraPose> PoseProvider::historyAt(double stamp, double max_gap) const {
  std::lock_guard<std::mutex> lock(history_mutex_);
  return history_.at(stamp, max_gap);
}

void PoseProvider::record(const ros::Time& stamp, const core::CameraPose& pose) {
  if (!pose.isValid()) return;
  std::lock_guard<std::mutex> lock(history_mutex_);
  history_.add(stamp.toSec(), pose);
}

// ---------------------------------------------------------------------------------------------
// tf

namespace {
/// A stamp more than `threshold` before `newest` (a zero stamp, "unknown", never is).
bool jumpsBack(const ros::Time& stamp, const ros::Time& newest, double threshold) {
  return threshold > 0.0 && !newest.isZero() && !stamp.isZero() &&
         (newest - stamp).toSec() > threshold;
}
}  // namespace

TfPoseProvider::TfPoseProvider(const NodeConfig& config, ros::NodeHandle nh)
    : config_(config),
      correction_frame_(config.correctionFrame()),
      buffer_(ros::Duration(kCacheSeconds)),
      tf_spinner_(1, &tf_queue_) {
  nh.setCallbackQueue(&tf_queue_);
  tf_sub_ = nh.subscribe<tf2_msgs::TFMessage>(
      "/tf", kTfQueue,
      [this](const ros::MessageEvent<tf2_msgs::TFMessage const>& e) { onTf(e, false); });
  tf_static_sub_ = nh.subscribe<tf2_msgs::TFMessage>(
      "/tf_static", kTfQueue,
      [this](const ros::MessageEvent<tf2_msgs::TFMessage const>& e) { onTf(e, true); });
  tf_spinner_.start();
}

TfPoseProvider::~TfPoseProvider() {
  tf_spinner_.stop();
  tf_sub_.shutdown();
  tf_static_sub_.shutdown();
}

void TfPoseProvider::clearLocked() {
  buffer_.clear();  // static transforms stay
  newest_.clear();
  links_.clear();
}

namespace {
bool sameTransform(const geometry_msgs::TransformStamped& a,
                   const geometry_msgs::TransformStamped& b) {
  const auto& p = a.transform.translation;
  const auto& q = b.transform.translation;
  const auto& r = a.transform.rotation;
  const auto& o = b.transform.rotation;
  return a.header.frame_id == b.header.frame_id && p.x == q.x && p.y == q.y && p.z == q.z &&
         r.x == o.x && r.y == o.y && r.z == o.z && r.w == o.w;
}
}  // namespace

void TfPoseProvider::noteLinkLocked(const geometry_msgs::TransformStamped& t,
                                    const std::string& authority) {
  auto [it, first] = links_.try_emplace(t.child_frame_id);
  Link& link = it->second;
  if (first || t.header.stamp < link.first.header.stamp) {
    if (!first) link.moved = link.moved || !sameTransform(t, link.first);
    link.first = t;
    return;
  }
  if (link.moved || link.extended) return;
  if (!sameTransform(t, link.first)) {
    link.moved = true;
    return;
  }
  // Seen twice, the same: a fixed link. It held before its first message too.
  link.extended = true;
  geometry_msgs::TransformStamped earlier = link.first;
  const double back = std::min(kFixedLinkBackfill, earlier.header.stamp.toSec());
  earlier.header.stamp -= ros::Duration(back);
  try {
    buffer_.setTransform(earlier, authority, false);
  } catch (const tf2::TransformException&) {
    // Older than the buffer keeps: nothing to extend.
  }
}

void TfPoseProvider::onTf(const ros::MessageEvent<tf2_msgs::TFMessage const>& event,
                          bool is_static) {
  const std::string authority = event.getPublisherName();
  std::lock_guard<std::mutex> lock(tf_mutex_);
  // As tf2_ros::TransformListener: ROS time went back (a bag played again with --clock).
  const ros::Time now = ros::Time::now();
  if (now < last_update_) {
    ROS_WARN_STREAM("view_selection: ROS time went back from " << stampText(last_update_) << " to "
                                                               << stampText(now)
                                                               << "; clearing the tf buffer");
    clearLocked();
    timeline_started_ = true;
  }
  last_update_ = now;
  for (const geometry_msgs::TransformStamped& t : event.getMessage()->transforms) {
    if (!is_static) {
      ros::Time& newest = newest_[t.child_frame_id];
      if (jumpsBack(t.header.stamp, newest, config_.time_jump_threshold)) {
        clearLocked();  // the old timeline's transforms, of every frame
        timeline_started_ = true;
      }
      ros::Time& latest = newest_[t.child_frame_id];  // clearLocked() may have removed it
      latest = std::max(latest, t.header.stamp);
    }
    try {
      buffer_.setTransform(t, authority, is_static);
      if (!is_static) noteLinkLocked(t, authority);
    } catch (const tf2::TransformException& e) {
      ROS_ERROR_STREAM_THROTTLE(5.0, "view_selection: tf from " << authority << ": " << e.what());
    }
  }
}

void TfPoseProvider::newTimeline(const ros::Time& stamp) {
  std::lock_guard<std::mutex> lock(tf_mutex_);
  // Old transforms are those of a frame that reaches beyond the new stamp (the old timeline
  // went on past it); a frame seen for the first time since is the new timeline's.
  bool old = false;
  for (const auto& [child, newest] : newest_)
    old = old || jumpsBack(stamp, newest, config_.time_jump_threshold);
  if (!timeline_started_ && old) clearLocked();
  timeline_started_ = false;
}

std::string TfPoseProvider::describe() const {
  return "tf (" + config_.world_frame + " <- " +
         (config_.camera_frame.empty() ? std::string("image frame_id") : config_.camera_frame) +
         ")";
}

PoseLookup TfPoseProvider::lookup(const std::string& image_frame, const ros::Time& stamp) {
  PoseLookup out;
  const std::string camera = config_.camera_frame.empty() ? image_frame : config_.camera_frame;
  if (camera.empty()) {
    out.reason = "no_pose";
    out.message =
        "the image has no frame_id and ~camera_frame is not set, so there is no frame to look up";
    return out;
  }
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(config_.pose_timeout);
  std::string error;
  while (true) {
    error.clear();
    if (buffer_.canTransform(config_.world_frame, camera, stamp, &error)) break;
    if (stopping_ || ros::WallTime::now() >= deadline || !ros::ok()) {
      out.reason = "no_pose";
      out.message = "no transform " + config_.world_frame + " <- " + camera + " at " +
                    stampText(stamp) + " within " + seconds(config_.pose_timeout) +
                    " (~pose_timeout): " + error;
      return out;
    }
    ros::WallDuration(kPollPeriod).sleep();
  }
  std::string target = config_.world_frame;
  try {
    const core::CameraPose pose =
        poseFromTransform(buffer_.lookupTransform(target, camera, stamp).transform);
    if (!correction_frame_.empty()) {
      // Part of the chain world <- camera (odom <- ... <- camera) when ~odom_frame is on it, so
      // no further wait; a frame off it fails here and the frame is dropped (no_pose).
      target = correction_frame_;
      out.uncorrected = poseFromTransform(buffer_.lookupTransform(target, camera, stamp).transform);
    }
    out.pose = pose;
    record(stamp, out.uncorrected.value_or(pose));
  } catch (const tf2::TransformException& e) {
    out.reason = "no_pose";
    out.message = "no transform " + target + " <- " + camera + " at " + stampText(stamp) +
                  (target == config_.world_frame ? "" : " (~odom_frame)") + ": " + e.what();
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Topic

namespace {

ReceivedPose fromPoseStamped(const geometry_msgs::PoseStamped& m) {
  return {m.header.stamp, normaliseFrameId(m.header.frame_id), "", poseFromMsg(m.pose)};
}
ReceivedPose fromOdometry(const nav_msgs::Odometry& m) {
  return {m.header.stamp, normaliseFrameId(m.header.frame_id), normaliseFrameId(m.child_frame_id),
          poseFromMsg(m.pose.pose)};
}
ReceivedPose fromPoseWithCovariance(const geometry_msgs::PoseWithCovarianceStamped& m) {
  return {m.header.stamp, normaliseFrameId(m.header.frame_id), "", poseFromMsg(m.pose.pose)};
}

const char* typeName(PoseSource source) {
  switch (source) {
    case PoseSource::kOdometry:
      return "nav_msgs/Odometry";
    case PoseSource::kPoseWithCovariance:
      return "geometry_msgs/PoseWithCovarianceStamped";
    default:
      return "geometry_msgs/PoseStamped";
  }
}

}  // namespace

TopicPoseProvider::TopicPoseProvider(const NodeConfig& config, ros::NodeHandle nh)
    : config_(config), nh_(nh), extrinsic_(nh), spinner_(1, &queue_) {
  if (config_.pose_source == PoseSource::kOdometry)
    subscribe<nav_msgs::Odometry>(&fromOdometry);
  else if (config_.pose_source == PoseSource::kPoseWithCovariance)
    subscribe<geometry_msgs::PoseWithCovarianceStamped>(&fromPoseWithCovariance);
  else
    subscribe<geometry_msgs::PoseStamped>(&fromPoseStamped);
  spinner_.start();
}

template <typename M>
void TopicPoseProvider::subscribe(ReceivedPose (*convert)(const M&)) {
  ros::SubscribeOptions options = ros::SubscribeOptions::create<M>(
      "pose", kSubscriberQueue,
      [this, convert](const boost::shared_ptr<const M>& m) { onPose(convert(*m)); }, ros::VoidPtr(),
      &queue_);
  subscriber_ = nh_.subscribe(options);
}

TopicPoseProvider::~TopicPoseProvider() {
  stop();
  spinner_.stop();
  subscriber_.shutdown();
}

std::string TopicPoseProvider::describe() const {
  return "'" + nh_.resolveName("pose") + "' (" + typeName(config_.pose_source) + ", of " +
         (config_.body_frame.empty() ? std::string("the optical frame") : config_.body_frame) + ")";
}

bool TopicPoseProvider::addPose(std::deque<ReceivedPose>& poses, ReceivedPose pose,
                                double time_jump) {
  const bool jump = !poses.empty() && jumpsBack(pose.stamp, poses.back().stamp, time_jump);
  if (jump) poses.clear();  // another timeline: a bag played again, a restarted SLAM system
  auto at =
      std::upper_bound(poses.begin(), poses.end(), pose.stamp,
                       [](const ros::Time& t, const ReceivedPose& p) { return t < p.stamp; });
  poses.insert(at, std::move(pose));
  // Frames older than the history are long dropped.
  const ros::Time newest = poses.back().stamp;
  while (poses.size() > kMaxPoses ||
         (poses.size() > 1 && newest.toSec() - poses.front().stamp.toSec() > kHistorySeconds))
    poses.pop_front();
  return jump;
}

void TopicPoseProvider::onPose(ReceivedPose pose) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (addPose(poses_, std::move(pose), config_.time_jump_threshold)) timeline_started_ = true;
  }
  arrived_.notify_all();
}

void TopicPoseProvider::reset() {
  PoseProvider::reset();
  std::lock_guard<std::mutex> lock(mutex_);
  poses_.clear();
}

void TopicPoseProvider::newTimeline(const ros::Time& stamp) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!timeline_started_ && !poses_.empty() &&
      jumpsBack(stamp, poses_.back().stamp, config_.time_jump_threshold))
    poses_.clear();
  timeline_started_ = false;
}

void TopicPoseProvider::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  extrinsic_.stop();
  arrived_.notify_all();
}

std::optional<ReceivedPose> TopicPoseProvider::bodyPoseAt(const std::deque<ReceivedPose>& poses,
                                                          const ros::Time& stamp,
                                                          double max_difference, PoseLookup& out) {
  const auto after =
      std::lower_bound(poses.begin(), poses.end(), stamp,
                       [](const ReceivedPose& p, const ros::Time& t) { return p.stamp < t; });
  if (after != poses.end() && after->stamp == stamp) return *after;  // exact: as it is
  const ReceivedPose* before = after == poses.begin() ? nullptr : &*(after - 1);
  const ReceivedPose* next = after == poses.end() ? nullptr : &*after;
  const auto far = [&](const ReceivedPose* p) {
    return !p || std::abs((p->stamp - stamp).toSec()) > max_difference;
  };
  if (far(before) || far(next)) {
    out.reason = "no_pose";
    std::ostringstream s;
    s << "no poses within " << seconds(max_difference) << " (~pose_max_time_difference) on both "
      << "sides of " << stampText(stamp) << " to interpolate between (nearest before: "
      << (before ? stampText(before->stamp) : std::string("none"))
      << ", after: " << (next ? stampText(next->stamp) : std::string("none")) << ")";
    out.message = s.str();
    return std::nullopt;
  }
  if (before->frame != next->frame || before->child_frame != next->child_frame) {
    out.reason = "bad_pose";
    out.message = "the poses around " + stampText(stamp) + " are in different frames ('" +
                  before->frame + "' and '" + next->frame + "')";
    return std::nullopt;
  }
  ReceivedPose p = *before;
  p.stamp = stamp;
  // Times relative to the first pose: at ~1.3e9 s a double resolves only 0.24 us.
  p.pose = core::interpolatePose({0.0, before->pose},
                                 {(next->stamp - before->stamp).toSec(), next->pose},
                                 (stamp - before->stamp).toSec());
  return p;
}

PoseLookup TopicPoseProvider::lookup(const std::string& image_frame, const ros::Time& stamp) {
  PoseLookup out;
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(config_.pose_timeout);
  std::optional<ReceivedPose> body;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    // Wait until a pose at or after the stamp is there (or the timeout).
    arrived_.wait_until(lock, deadline, [&] {
      return stopping_ || (!poses_.empty() && poses_.back().stamp >= stamp);
    });
    body = bodyPoseAt(poses_, stamp, config_.pose_max_time_difference, out);
  }
  if (!body) {
    if (out.reason == "no_pose")
      out.message = "on '" + nh_.resolveName("pose") + "': " + out.message + " after waiting " +
                    seconds(config_.pose_timeout) + " (~pose_timeout)";
    return out;
  }
  if (body->frame != config_.world_frame) {
    out.reason = "bad_pose";
    out.message = "the pose is in frame '" + body->frame + "', not ~world_frame '" +
                  config_.world_frame + "'";
    return out;
  }
  if (!body->pose.isValid()) {
    out.reason = "bad_pose";
    out.message = "the pose on '" + nh_.resolveName("pose") + "' is not finite";
    return out;
  }
  const std::string camera = config_.camera_frame.empty() ? image_frame : config_.camera_frame;
  const std::string body_frame = !config_.body_frame.empty()  ? config_.body_frame
                                 : !body->child_frame.empty() ? body->child_frame
                                                              : camera;
  if (body_frame == camera) {
    out.pose = body->pose;
    record(stamp, *out.pose);
    return out;
  }
  std::string error;
  const auto remaining =
      std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count();
  const std::optional<core::CameraPose> extrinsic =
      extrinsic_.lookup(body_frame, camera, std::max(remaining, 0.0), &error);
  if (!extrinsic) {
    out.reason = "no_pose";
    out.message = "the poses are of '" + body_frame + "', but tf has no transform " + body_frame +
                  " <- " + camera + " (the camera's optical frame; ~camera_frame) within " +
                  seconds(config_.pose_timeout) + ": " + error;
    return out;
  }
  out.pose = core::composePoses(body->pose, *extrinsic);
  record(stamp, *out.pose);
  return out;
}

std::unique_ptr<PoseProvider> makePoseProvider(const NodeConfig& config, ros::NodeHandle nh) {
  if (config.pose_source == PoseSource::kTf) return std::make_unique<TfPoseProvider>(config, nh);
  return std::make_unique<TopicPoseProvider>(config, nh);
}

}  // namespace view_selection::ros_node
