#include "view_selection/ros/input_statistics.h"

#include <ros/console.h>

#include <algorithm>
#include <sstream>

namespace view_selection::ros_node {

std::string stampText(const ros::Time& t) {
  std::ostringstream s;
  s.precision(6);
  s << std::fixed << t.toSec();
  return s.str();
}

uint64_t InputStatistics::Counts::dropped_total() const {
  uint64_t total = 0;
  for (const auto& [reason, count] : dropped) total += count;
  return total;
}

void InputStatistics::arrived(Input input) {
  std::lock_guard<std::mutex> lock(mutex_);
  switch (input) {
    case Input::kImage:
      ++counts_.images_arrived;
      break;
    case Input::kCameraInfo:
      ++counts_.camera_infos_arrived;
      break;
    case Input::kDepth:
      ++counts_.depths_arrived;
      break;
  }
  ++version_;
}

void InputStatistics::setImagesInSynchroniser(uint64_t images) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (counts_.images_in_synchroniser == images) return;
  counts_.images_in_synchroniser = images;
  ++version_;
}

void InputStatistics::pathApplied(uint64_t keyframes) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++counts_.paths_applied;
  counts_.keyframes_corrected += keyframes;
  ++version_;
}

void InputStatistics::frameReceived() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++counts_.frames_received;
  ++version_;
}

void InputStatistics::frameOffered(double insertion_seconds) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++counts_.frames_offered;
  if (insertion_seconds >= 0.0) {
    counts_.last_insertion_seconds = insertion_seconds;
    counts_.max_insertion_seconds = std::max(counts_.max_insertion_seconds, insertion_seconds);
    counts_.last_insertion = ros::WallTime::now();
  }
  ++version_;
}

void InputStatistics::drop(const std::string& reason, const std::string& message,
                           const ros::Time& stamp) {
  uint64_t suppressed = 0;
  bool log = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counts_.dropped[reason];
    counts_.last_error = reason + ": " + message;
    counts_.last_error_stamp = stamp;
    ++version_;
    Throttle& t = throttle_[reason];
    const ros::WallTime now = ros::WallTime::now();
    if (t.last.isZero() || (now - t.last).toSec() >= kLogPeriod) {
      log = true;
      suppressed = t.suppressed;
      t.suppressed = 0;
      t.last = now;
    } else {
      ++t.suppressed;
    }
  }
  if (log)
    ROS_WARN_STREAM(
        "view_selection: dropped input at "
        << stampText(stamp) << " (" << reason << "): " << message
        << (suppressed ? " [" + std::to_string(suppressed) + " more such drops not logged]" : ""));
}

void InputStatistics::reset() {
  std::lock_guard<std::mutex> lock(mutex_);
  counts_ = Counts{};
  ++version_;
}

InputStatistics::Counts InputStatistics::counts() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return counts_;
}

uint64_t InputStatistics::version() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return version_;
}

view_selection::InputStatistics InputStatistics::toMsg(uint32_t keyframes) const {
  view_selection::InputStatistics msg;
  msg.header.stamp = ros::Time::now();
  msg.keyframes = keyframes;
  std::lock_guard<std::mutex> lock(mutex_);
  msg.images_arrived = counts_.images_arrived;
  msg.camera_infos_arrived = counts_.camera_infos_arrived;
  msg.depths_arrived = counts_.depths_arrived;
  msg.frames_received = counts_.frames_received;
  msg.images_in_synchroniser = counts_.images_in_synchroniser;
  msg.paths_applied = counts_.paths_applied;
  msg.keyframes_corrected = counts_.keyframes_corrected;
  msg.frames_offered = counts_.frames_offered;
  for (const auto& [reason, count] : counts_.dropped) {
    msg.drop_reasons.push_back(reason);
    msg.drop_counts.push_back(count);
    msg.frames_dropped += count;
  }
  msg.last_error = counts_.last_error;
  msg.last_error_stamp = counts_.last_error_stamp;
  msg.last_insertion_seconds = counts_.last_insertion_seconds;
  msg.max_insertion_seconds = counts_.max_insertion_seconds;
  return msg;
}

}  // namespace view_selection::ros_node
