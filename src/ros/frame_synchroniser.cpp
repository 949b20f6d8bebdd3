#include "view_selection/ros/frame_synchroniser.h"

#include "view_selection/core/parameters.h"

#include <algorithm>
#include <cmath>

namespace view_selection::ros_node {

namespace {

template <typename P>
void insertByStamp(std::deque<P>& messages, P partner) {
  const auto at =
      std::upper_bound(messages.begin(), messages.end(), partner.message->header.stamp,
                       [](const ros::Time& t, const P& m) { return t < m.message->header.stamp; });
  messages.insert(at, std::move(partner));
}

/// Whether a later message could still be nearer to `stamp`: not once one at the stamp came, or
/// one after it that arrived after the image (an input's stamps increase as they arrive; a
/// message that arrived before the image may be one of an earlier burst).
template <typename P>
bool decided(const std::deque<P>& messages, const ros::Time& stamp, uint64_t image_order) {
  auto it =
      std::lower_bound(messages.begin(), messages.end(), stamp,
                       [](const P& m, const ros::Time& t) { return m.message->header.stamp < t; });
  for (; it != messages.end(); ++it)
    if (it->message->header.stamp == stamp || it->order > image_order) return true;
  return false;
}

/// The message nearest to `stamp` (the earlier of two equally near), or null.
template <typename P>
auto nearest(const std::deque<P>& messages, const ros::Time& stamp, double* offset) {
  decltype(P::message) best;
  if (messages.empty()) return best;
  auto after =
      std::lower_bound(messages.begin(), messages.end(), stamp,
                       [](const P& m, const ros::Time& t) { return m.message->header.stamp < t; });
  if (after != messages.end()) best = after->message;
  if (after != messages.begin()) {
    const auto& before = (after - 1)->message;
    if (!best || (stamp - before->header.stamp).toSec() <= (best->header.stamp - stamp).toSec())
      best = before;
  }
  *offset = (best->header.stamp - stamp).toSec();
  return best;
}

std::string seconds(double s) { return core::formatNumber(std::round(s * 1e6) / 1e6) + " s"; }

}  // namespace

SynchronisedFrames FrameSynchroniser::addImage(const sensor_msgs::ImageConstPtr& image,
                                               double now, uint64_t generation) {
  waiting_.push_back({image, now, ++arrivals_, generation});
  newest_image_ = std::max(newest_image_, image->header.stamp);
  SynchronisedFrames out;
  release(now, out);
  return out;
}

SynchronisedFrames FrameSynchroniser::addCameraInfo(const sensor_msgs::CameraInfoConstPtr& info,
                                                    double now) {
  newTimelineIfJump(infos_, info->header.stamp);
  info_arrived_ = now;
  insertByStamp(infos_, Partner<sensor_msgs::CameraInfoConstPtr>{info, ++arrivals_});
  SynchronisedFrames out;
  release(now, out);
  return out;
}

SynchronisedFrames FrameSynchroniser::addDepth(const sensor_msgs::ImageConstPtr& depth,
                                               double now) {
  if (!config_.use_depth) return {};
  newTimelineIfJump(depths_, depth->header.stamp);
  depth_arrived_ = now;
  insertByStamp(depths_, Partner<sensor_msgs::ImageConstPtr>{depth, ++arrivals_});
  SynchronisedFrames out;
  release(now, out);
  return out;
}

SynchronisedFrames FrameSynchroniser::poll(double now) {
  SynchronisedFrames out;
  release(now, out);
  return out;
}

void FrameSynchroniser::clear() {
  waiting_.clear();
  infos_.clear();
  depths_.clear();
  last_released_ = ros::Time();
  newest_image_ = ros::Time();
  info_arrived_ = depth_arrived_ = 0.0;
}

namespace {
/// A stamp more than `threshold` before `newest` (a zero stamp, "unknown", never is).
bool jumpsBack(const ros::Time& stamp, const ros::Time& newest, double threshold) {
  return threshold > 0.0 && !newest.isZero() && !stamp.isZero() &&
         (newest - stamp).toSec() > threshold;
}
}  // namespace

bool FrameSynchroniser::isTimeJump(const ros::Time& stamp, ros::Time* newest) const {
  if (!jumpsBack(stamp, newest_image_, config_.time_jump)) return false;
  if (newest) *newest = newest_image_;
  return true;
}

void FrameSynchroniser::startTimeline() {
  waiting_.clear();
  newest_image_ = ros::Time();
  // Released stamps of the old timeline would keep no partner of the new one from pruning.
  last_released_ = ros::Time();
}

size_t FrameSynchroniser::discardWaitingBefore(uint64_t generation) {
  const size_t before = waiting_.size();
  waiting_.erase(std::remove_if(waiting_.begin(), waiting_.end(),
                                [&](const Waiting& w) { return w.generation < generation; }),
                 waiting_.end());
  // The new session starts over: an image earlier than the old one's is no time jump.
  newest_image_ = ros::Time();
  for (const Waiting& w : waiting_) newest_image_ = std::max(newest_image_, w.image->header.stamp);
  return before - waiting_.size();
}

template <typename P>
void FrameSynchroniser::newTimelineIfJump(std::deque<P>& messages, const ros::Time& stamp) {
  if (messages.empty()) return;
  // The newest of this input: stamps are kept ascending.
  if (jumpsBack(stamp, messages.back().message->header.stamp, config_.time_jump))
    messages.clear();
}

void FrameSynchroniser::release(double now, SynchronisedFrames& out) {
  while (!waiting_.empty()) {
    const Waiting& head = waiting_.front();
    const ros::Time stamp = head.image->header.stamp;
    const bool info_decided = decided(infos_, stamp, head.order);
    const bool depth_decided = !config_.use_depth || decided(depths_, stamp, head.order);
    const bool ready = info_decided && depth_decided;
    // The wait counts from the image's arrival, or from the last message of the input it lacks
    // when that came later: such a message is stamped before the image (else it would decide
    // it), so that input lags behind and is still coming. The quietest lacking input counts.
    double since = head.arrived;
    if (!ready) {
      double lacking = info_decided ? depth_arrived_
                                    : (depth_decided ? info_arrived_
                                                     : std::min(info_arrived_, depth_arrived_));
      since = std::max(since, lacking);
    }
    const bool too_many = waiting_.size() > config_.max_waiting;
    double info_offset = 0.0, depth_offset = 0.0;
    const sensor_msgs::CameraInfoConstPtr info = nearest(infos_, stamp, &info_offset);
    const sensor_msgs::ImageConstPtr depth =
        config_.use_depth ? nearest(depths_, stamp, &depth_offset) : sensor_msgs::ImageConstPtr();
    const auto tooFar = [&](double offset) {
      return config_.max_spread > 0.0 && std::abs(offset) > config_.max_spread;
    };
    // With partners near enough already, waiting only looks for nearer ones (a bag's last image
    // waits for a later depth that never comes): `timeout`. Without, the image is lost unless
    // its partner still comes (a stalled connection): the longer `unmatched_timeout`.
    const bool matched = info && !tooFar(info_offset) &&
                         (!config_.use_depth || (depth && !tooFar(depth_offset)));
    const double limit =
        matched ? config_.timeout : std::max(config_.timeout, config_.unmatched_timeout);
    if (!ready && now - since < limit && !too_many) break;
    std::string missing;
    if (!info)
      missing = "no camera_info has arrived";
    else if (tooFar(info_offset))
      missing = "the nearest camera_info is " + seconds(info_offset) + " from it";
    else if (config_.use_depth && !depth)
      missing = "no depth image has arrived";
    else if (config_.use_depth && tooFar(depth_offset))
      missing = "the nearest depth image is " + seconds(depth_offset) + " from it";
    if (missing.empty()) {
      out.frames.push_back({head.image, info, depth, head.generation});
      if (!ready) ++out.undecided;
    } else {
      out.drops.push_back({stamp, "no partner for the image within " + seconds(config_.max_spread) +
                                      " (~max_stamp_spread): " + missing +
                                      (ready ? std::string()
                                       : too_many
                                           ? " (" + std::to_string(waiting_.size()) +
                                                 " images were waiting, more than ~queue_size " +
                                                 std::to_string(config_.max_waiting) + ")"
                                           : " (after waiting " + seconds(now - head.arrived) +
                                                 ", " + seconds(now - since) +
                                                 " of them without a message of the missing "
                                                 "input: ~sync_unmatched_timeout)"),
                           head.generation});
    }
    last_released_ = std::max(last_released_, stamp);
    waiting_.pop_front();
  }
  prune();
}

void FrameSynchroniser::prune() {
  // Partners of released images may still serve the next one, and every waiting image keeps
  // what could be its partner; older ones cannot serve anything, unless they arrived recently
  // (the partner of an out-of-order image may come before the image).
  if (last_released_.isZero()) return;
  ros::Time oldest = last_released_;
  for (const Waiting& w : waiting_) oldest = std::min(oldest, w.image->header.stamp);
  const double keep = config_.max_spread > 0.0 ? config_.max_spread : 1.0;
  const uint64_t recent = 3 * static_cast<uint64_t>(config_.max_waiting) + 6;
  const auto old = [&](const auto& partner) {
    return (oldest - partner.message->header.stamp).toSec() > keep &&
           partner.order + recent < arrivals_;
  };
  while (infos_.size() > 1 && old(infos_[0]) && old(infos_[1])) infos_.pop_front();
  while (depths_.size() > 1 && old(depths_[0]) && old(depths_[1])) depths_.pop_front();
  while (infos_.size() > config_.max_partners) infos_.pop_front();
  while (depths_.size() > config_.max_partners) depths_.pop_front();
}

}  // namespace view_selection::ros_node
