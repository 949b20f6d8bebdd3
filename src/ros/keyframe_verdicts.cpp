#include "view_selection/ros/keyframe_verdicts.h"

#include <chrono>
#include <cmath>

namespace view_selection::ros_node {

KeyframeVerdicts::KeyframeVerdicts(const NodeConfig& config, ros::NodeHandle nh)
    : config_(config), nh_(nh) {
  active_ = config_.selector.keyframes.mode == core::KeyframeMode::kExternal;
  if (!active_) return;
  ros::SubscribeOptions options = ros::SubscribeOptions::create<nav_msgs::Path>(
      "keyframes", 10, [this](const nav_msgs::PathConstPtr& p) { onPath(p); }, ros::VoidPtr(),
      &queue_);
  subscriber_ = nh_.subscribe(options);
  spinner_ = std::make_unique<ros::AsyncSpinner>(1, &queue_);
  spinner_->start();
}

KeyframeVerdicts::~KeyframeVerdicts() {
  stop();
  if (spinner_) spinner_->stop();
  subscriber_.shutdown();
}

std::string KeyframeVerdicts::describe() const {
  return "the stamps on '" + nh_.resolveName("keyframes") + "'";
}

void KeyframeVerdicts::onPath(const nav_msgs::PathConstPtr& path) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ros::Time newest;
    for (const auto& p : path->poses) newest = std::max(newest, p.header.stamp);
    const double jump = config_.time_jump_threshold;
    if (jump > 0.0 && !newest.isZero() && !stamps_.empty() &&
        (*stamps_.rbegin() - newest).toSec() > jump) {
      // A path of another timeline (a restarted SLAM system, a bag played again).
      stamps_.clear();
      timeline_started_ = true;
    }
    for (const auto& p : path->poses) stamps_.insert(p.header.stamp);
    while (stamps_.size() > kMaxStamps) stamps_.erase(stamps_.begin());
  }
  arrived_.notify_all();
}

KeyframeVerdicts::Verdict KeyframeVerdicts::verdictLocked(const ros::Time& stamp) const {
  const ros::Duration tolerance(config_.keyframe_stamp_tolerance);
  const ros::Time lo = stamp > ros::Time(0) + tolerance ? stamp - tolerance : ros::Time(0);
  const auto it = stamps_.lower_bound(lo);
  if (it != stamps_.end() && *it <= stamp + tolerance) return Verdict::kKeyframe;
  if (!stamps_.empty() && *stamps_.rbegin() > stamp + tolerance) return Verdict::kNotKeyframe;
  return Verdict::kUnknown;
}

KeyframeVerdicts::Verdict KeyframeVerdicts::now(const ros::Time& stamp) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return verdictLocked(stamp);
}

KeyframeVerdicts::Verdict KeyframeVerdicts::wait(const ros::Time& stamp) {
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration<double>(config_.keyframe_verdict_timeout);
  std::unique_lock<std::mutex> lock(mutex_);
  const uint64_t resets = resets_;
  Verdict verdict = verdictLocked(stamp);
  arrived_.wait_until(lock, deadline, [&] {
    if (resets_ != resets) {  // the frame's session is over
      verdict = Verdict::kUnknown;
      return true;
    }
    verdict = verdictLocked(stamp);
    return stopping_ || verdict != Verdict::kUnknown;
  });
  return verdict;
}

void KeyframeVerdicts::reset() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stamps_.clear();
    timeline_started_ = false;
    ++resets_;
  }
  arrived_.notify_all();
}

void KeyframeVerdicts::newTimeline(const ros::Time& stamp) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const ros::Duration tolerance(config_.keyframe_stamp_tolerance);
    const ros::Time from = stamp > ros::Time(0) + tolerance ? stamp - tolerance : ros::Time(0);
    if (!timeline_started_) stamps_.erase(stamps_.lower_bound(from), stamps_.end());
    timeline_started_ = false;
    ++resets_;
  }
  arrived_.notify_all();
}

void KeyframeVerdicts::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  arrived_.notify_all();
}

}  // namespace view_selection::ros_node
