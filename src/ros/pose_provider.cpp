#include "view_selection/ros/pose_provider.h"

#include "view_selection/core/parameters.h"
#include "view_selection/ros/conversions.h"
#include "view_selection/ros/input_statistics.h"

#include <tf2/exceptions.h>

#include <algorithm>
#include <chrono>
#include <cmath>

namespace view_selection::ros_node {

namespace {
std::string seconds(double value) { return core::formatNumber(value) + " s"; }
}  // namespace

// ---------------------------------------------------------------------------------------------
// tf

TfPoseProvider::TfPoseProvider(const NodeConfig& config, ros::NodeHandle nh)
    : config_(config), buffer_(ros::Duration(kCacheSeconds)), listener_(buffer_, nh, true) {}

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
  try {
    out.pose =
        poseFromTransform(buffer_.lookupTransform(config_.world_frame, camera, stamp).transform);
  } catch (const tf2::TransformException& e) {
    out.reason = "no_pose";
    out.message = "no transform " + config_.world_frame + " <- " + camera + " at " +
                  stampText(stamp) + ": " + e.what();
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Topic

TopicPoseProvider::TopicPoseProvider(const NodeConfig& config, ros::NodeHandle nh)
    : config_(config), nh_(nh), spinner_(1, &queue_) {
  ros::SubscribeOptions options = ros::SubscribeOptions::create<geometry_msgs::PoseStamped>(
      "pose", kSubscriberQueue, [this](const geometry_msgs::PoseStampedConstPtr& p) { onPose(p); },
      ros::VoidPtr(), &queue_);
  subscriber_ = nh_.subscribe(options);
  spinner_.start();
}

TopicPoseProvider::~TopicPoseProvider() {
  stop();
  spinner_.stop();
  subscriber_.shutdown();
}

std::string TopicPoseProvider::describe() const { return "'" + nh_.resolveName("pose") + "'"; }

void TopicPoseProvider::onPose(const geometry_msgs::PoseStampedConstPtr& pose) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto at = std::upper_bound(poses_.begin(), poses_.end(), pose->header.stamp,
                               [](const ros::Time& t, const geometry_msgs::PoseStampedConstPtr& p) {
                                 return t < p->header.stamp;
                               });
    poses_.insert(at, pose);
    // Frames older than the history are long dropped.
    const ros::Time newest = poses_.back()->header.stamp;
    while (poses_.size() > kMaxPoses ||
           (poses_.size() > 1 &&
            newest.toSec() - poses_.front()->header.stamp.toSec() > kHistorySeconds))
      poses_.pop_front();
  }
  arrived_.notify_all();
}

void TopicPoseProvider::reset() {
  std::lock_guard<std::mutex> lock(mutex_);
  poses_.clear();
}

void TopicPoseProvider::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  arrived_.notify_all();
}

PoseLookup TopicPoseProvider::lookup(const std::string&, const ros::Time& stamp) {
  PoseLookup out;
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(config_.pose_timeout);
  std::unique_lock<std::mutex> lock(mutex_);
  // Wait until a pose at or after the stamp is there (or the timeout), then take the nearest.
  arrived_.wait_until(lock, deadline, [&] {
    return stopping_ || (!poses_.empty() && poses_.back()->header.stamp >= stamp);
  });
  geometry_msgs::PoseStampedConstPtr best;
  double best_dt = 0.0;
  for (const auto& p : poses_) {
    const double dt = std::abs((p->header.stamp - stamp).toSec());
    if (!best || dt < best_dt) {
      best = p;
      best_dt = dt;
    }
  }
  if (!best || best_dt > config_.pose_max_time_difference) {
    out.reason = "no_pose";
    out.message = "no pose on '" + nh_.resolveName("pose") + "' within " +
                  seconds(config_.pose_max_time_difference) + " of " + stampText(stamp) +
                  " (~pose_max_time_difference) after waiting " + seconds(config_.pose_timeout) +
                  " (~pose_timeout)";
    return out;
  }
  if (normaliseFrameId(best->header.frame_id) != config_.world_frame) {
    out.reason = "bad_pose";
    out.message = "the pose is in frame '" + best->header.frame_id + "', not ~world_frame '" +
                  config_.world_frame + "'";
    return out;
  }
  out.pose = poseFromMsg(best->pose);
  return out;
}

std::unique_ptr<PoseProvider> makePoseProvider(const NodeConfig& config, ros::NodeHandle nh) {
  if (config.pose_source == PoseSource::kTopic)
    return std::make_unique<TopicPoseProvider>(config, nh);
  return std::make_unique<TfPoseProvider>(config, nh);
}

}  // namespace view_selection::ros_node
