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

namespace {
/// Drop reasons that count inputs other than received frames: map clouds, paths, and images that
/// never became a frame (lost before the node, or without a partner in the synchroniser).
bool isFrameReason(const std::string& reason) {
  return reason != "bad_map" && reason != "bad_path" && reason != "lost_before_node" &&
         reason != "unsynchronised";
}
ros::Time rosTime(double seconds) { return seconds > 0.0 ? ros::Time(seconds) : ros::Time(); }
}  // namespace

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

void InputStatistics::pairedOnTimeout(uint64_t frames) {
  if (frames == 0) return;
  std::lock_guard<std::mutex> lock(mutex_);
  counts_.frames_paired_on_timeout += frames;
  ++version_;
}

void InputStatistics::pathApplied(uint64_t keyframes) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++counts_.paths_applied;
  counts_.keyframes_corrected += keyframes;
  ++version_;
}


uint64_t InputStatistics::Counts::frames_dropped() const {
  uint64_t total = 0;
  for (const auto& [reason, count] : dropped) total += isFrameReason(reason) ? count : 0;
  return total;
}

uint64_t InputStatistics::frameReceived() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++counts_.frames_received;
  ++version_;
  return session_;
}

void InputStatistics::frameOffered(uint64_t session, const ros::Time& stamp,
                                   double insertion_seconds) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (session != session_) return;  // received before a reset
  ++counts_.frames_offered;
  counts_.last_frame_stamp = stamp;
  if (insertion_seconds >= 0.0) {
    ++counts_.keyframes;
    counts_.last_insertion_seconds = insertion_seconds;
    counts_.max_insertion_seconds = std::max(counts_.max_insertion_seconds, insertion_seconds);
    counts_.last_insertion = ros::WallTime::now();
  }
  ++version_;
}

void InputStatistics::revisit(uint64_t session, bool registered) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (session != session_) return;  // received before a reset
  ++counts_.revisits;
  if (registered) ++counts_.revisits_registered;
  ++version_;
}

void InputStatistics::drop(uint64_t session, const std::string& reason, const std::string& message,
                           const ros::Time& stamp) {
  count(reason, message, stamp, &session);
}

void InputStatistics::dropInput(const std::string& reason, const std::string& message,
                                const ros::Time& stamp) {
  count(reason, message, stamp, nullptr);
}

void InputStatistics::count(const std::string& reason, const std::string& message,
                            const ros::Time& stamp, const uint64_t* session) {
  uint64_t suppressed = 0;
  bool log = false;
  const bool frame = session != nullptr;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // Checked under the lock reset() takes: a frame received before a reset is not this
    // session's, whenever its outcome arrives.
    if (session && *session != session_) return;
    ++counts_.dropped[reason];
    counts_.last_error = reason + ": " + message;
    counts_.last_error_stamp = stamp;
    // A frame the node stopped before handling was never considered: a replay after a restart
    // sends it again.
    if (frame && reason != kShutdownReason) counts_.last_frame_stamp = stamp;
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
  ++session_;
  ++version_;
}

void InputStatistics::timeJump() {
  std::lock_guard<std::mutex> lock(mutex_);
  const uint64_t jumps = counts_.time_jumps + 1;
  counts_ = Counts{};
  counts_.time_jumps = jumps;
  ++session_;
  ++version_;
}

uint64_t InputStatistics::session() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return session_;
}

session::SessionStatistics InputStatistics::toSaved() const {
  std::lock_guard<std::mutex> lock(mutex_);
  session::SessionStatistics s;
  s.frames_offered = counts_.frames_offered;
  s.frames_received = counts_.frames_offered + counts_.frames_dropped();
  s.dropped = counts_.dropped;
  s.last_error = counts_.last_error;
  s.last_error_stamp = counts_.last_error_stamp.toSec();
  s.last_insertion_seconds = counts_.last_insertion_seconds;
  s.max_insertion_seconds = counts_.max_insertion_seconds;
  if (!counts_.last_frame_stamp.isZero()) s.last_frame_stamp = counts_.last_frame_stamp.toSec();
  return s;
}

void InputStatistics::restore(const session::SessionStatistics& saved, uint64_t keyframes) {
  std::lock_guard<std::mutex> lock(mutex_);
  counts_ = Counts{};
  counts_.keyframes = keyframes;
  counts_.frames_received = saved.frames_received;
  counts_.frames_offered = saved.frames_offered;
  counts_.dropped = saved.dropped;
  counts_.last_error = saved.last_error;
  counts_.last_error_stamp = rosTime(saved.last_error_stamp);
  counts_.last_insertion_seconds = saved.last_insertion_seconds;
  counts_.max_insertion_seconds = saved.max_insertion_seconds;
  if (saved.last_frame_stamp) counts_.last_frame_stamp = rosTime(*saved.last_frame_stamp);
  ++session_;
  ++version_;
}

void InputStatistics::stateSaved(uint32_t keyframes, const ros::Time& frame_stamp) {
  std::lock_guard<std::mutex> lock(mutex_);
  saved_keyframes_ = keyframes;
  saved_frame_stamp_ = frame_stamp;
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

view_selection::InputStatistics InputStatistics::toMsg() const {
  view_selection::InputStatistics msg;
  msg.header.stamp = ros::Time::now();
  std::lock_guard<std::mutex> lock(mutex_);
  msg.images_arrived = counts_.images_arrived;
  msg.camera_infos_arrived = counts_.camera_infos_arrived;
  msg.depths_arrived = counts_.depths_arrived;
  msg.frames_received = counts_.frames_received;
  msg.images_in_synchroniser = counts_.images_in_synchroniser;
  msg.frames_paired_on_timeout = counts_.frames_paired_on_timeout;
  msg.paths_applied = counts_.paths_applied;
  msg.keyframes_corrected = counts_.keyframes_corrected;
  msg.frames_offered = counts_.frames_offered;
  msg.keyframes = static_cast<uint32_t>(counts_.keyframes);
  msg.revisits = counts_.revisits;
  msg.revisits_registered = counts_.revisits_registered;
  msg.time_jumps = counts_.time_jumps;
  for (const auto& [reason, count] : counts_.dropped) {
    msg.drop_reasons.push_back(reason);
    msg.drop_counts.push_back(count);
    msg.frames_dropped += count;
  }
  msg.last_error = counts_.last_error;
  msg.last_error_stamp = counts_.last_error_stamp;
  msg.last_frame_stamp = counts_.last_frame_stamp;
  msg.last_insertion_seconds = counts_.last_insertion_seconds;
  msg.max_insertion_seconds = counts_.max_insertion_seconds;
  msg.state_saved_keyframes = saved_keyframes_;
  msg.state_saved_frame_stamp = saved_frame_stamp_;
  return msg;
}

}  // namespace view_selection::ros_node
