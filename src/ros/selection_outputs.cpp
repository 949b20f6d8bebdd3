#include "view_selection/ros/selection_outputs.h"

#include "view_selection/ros/conversions.h"
#include "view_selection/ros/markers.h"

#include <diagnostic_msgs/DiagnosticStatus.h>
#include <view_selection/InputStatistics.h>
#include <view_selection/ViewSelection.h>
#include <visualization_msgs/MarkerArray.h>

#include <algorithm>
#include <sstream>

namespace view_selection::ros_node {

SelectionOutputs::SelectionOutputs(const NodeConfig& config, ros::NodeHandle nh,
                                   ros::NodeHandle private_nh, const KeyframeWorker& worker,
                                   const InputStatistics& statistics)
    : config_(config), worker_(worker), statistics_(statistics), diagnostics_(nh, private_nh) {
  // Bounded updates are deltas: a queue, so that a subscriber that keeps up misses none.
  selection_pub_ =
      private_nh.advertise<view_selection::ViewSelection>("selection", kSelectionQueue, true);
  markers_pub_ = private_nh.advertise<visualization_msgs::MarkerArray>("markers", 1, true);
  statistics_pub_ = private_nh.advertise<view_selection::InputStatistics>("statistics", 1, true);
  diagnostics_.setHardwareID(config_.camera_frame.empty() ? "camera" : config_.camera_frame);
  diagnostics_.add("view selection", this, &SelectionOutputs::diagnose);
  update();
  timer_ =
      private_nh.createWallTimer(ros::WallDuration(std::max(config_.publish_period, kMinPeriod)),
                                 [this](const ros::WallTimerEvent&) { update(); });
  diagnostics_timer_ = private_nh.createWallTimer(
      ros::WallDuration(kDiagnosticsPeriod),
      [this](const ros::WallTimerEvent&) { diagnostics_.force_update(); });
}

SelectionOutputs::~SelectionOutputs() {
  timer_.stop();
  diagnostics_timer_.stop();
}

void SelectionOutputs::setPublishPeriod(double seconds) {
  timer_.setPeriod(ros::WallDuration(std::max(seconds, kMinPeriod)));
}

void SelectionOutputs::update() {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::shared_ptr<const ServedSelection> snapshot = worker_.served();
  const core::SelectionOutput& s = snapshot->selection;
  const bool changed = snapshot->version != published_version_;
  if (changed || pending_views_ > 0) {
    const size_t max_views = static_cast<size_t>(std::max(0, config_.publish_max_views));
    view_selection::ViewSelection msg;
    if (max_views == 0 || s.size() <= max_views) {
      msg = selectionToMsg(s, config_.world_frame);
      tracker_.markAll(s);
      pending_views_ = 0;
    } else {
      msg = selectionUpdateToMsg(s, config_.world_frame,
                                 tracker_.take(s, max_views, &pending_views_));
      msg.pending_views = static_cast<uint32_t>(pending_views_);
    }
    msg.update = ++updates_;
    selection_pub_.publish(msg);
  }
  if (changed) {
    markers_pub_.publish(selectionMarkers(s, config_.world_frame, config_.marker_scale,
                                          static_cast<size_t>(std::max(0, config_.publish_max_views))));
    published_version_ = snapshot->version;
  }
  const uint64_t stats_version = statistics_.version();
  if (stats_version != published_stats_version_) {
    statistics_pub_.publish(statistics_.toMsg());
    published_stats_version_ = stats_version;
  }
}

ViewChangeTracker::Sent ViewChangeTracker::record(const core::SelectionOutput& snapshot,
                                                  size_t i) {
  const core::KeyframeSummary& kf = snapshot.keyframes[i];
  const core::ChunkedSelection& selection = snapshot.selection;
  Sent sent;
  sent.valid = true;
  sent.stamp = kf.stamp;
  sent.num_points = kf.num_points;
  sent.pose = kf.pose;
  sent.selected = i < selection.next_views.size() ? selection.next_views[i].size() : 0;
  if (i < selection.final_next_views.size()) sent.final = selection.final_next_views[i];
  sent.row_version = snapshot.table.rowVersion(static_cast<core::ViewId>(i));
  return sent;
}

bool ViewChangeTracker::same(const Sent& sent, const core::SelectionOutput& snapshot, size_t i) {
  const core::KeyframeSummary& kf = snapshot.keyframes[i];
  const core::ChunkedSelection& selection = snapshot.selection;
  static const core::NextViewSet kEmpty;
  const size_t selected = i < selection.next_views.size() ? selection.next_views[i].size() : 0;
  const core::NextViewSet& final =
      i < selection.final_next_views.size() ? selection.final_next_views[i] : kEmpty;
  return sent.valid && sent.stamp == kf.stamp && sent.num_points == kf.num_points &&
         sent.pose.position == kf.pose.position &&
         sent.pose.orientation.coeffs() == kf.pose.orientation.coeffs() &&
         sent.selected == selected && sent.final == final &&
         sent.row_version == snapshot.table.rowVersion(static_cast<core::ViewId>(i));
}

std::vector<core::ViewId> ViewChangeTracker::take(const core::SelectionOutput& snapshot,
                                                  size_t limit, size_t* pending) {
  const size_t n = snapshot.size();
  if (sent_.size() > n) sent_.resize(n);  // after a reset
  std::vector<core::ViewId> views;
  size_t left_out = 0;
  if (cursor_ >= n) cursor_ = 0;
  size_t next_cursor = cursor_;
  for (size_t step = 0; step < n; ++step) {
    const size_t i = (cursor_ + step) % n;
    if (i < sent_.size() && same(sent_[i], snapshot, i)) continue;
    if (views.size() >= limit) {
      ++left_out;
      continue;
    }
    if (i >= sent_.size()) sent_.resize(i + 1);
    sent_[i] = record(snapshot, i);
    views.push_back(static_cast<core::ViewId>(i));
    next_cursor = (i + 1) % n;
  }
  cursor_ = next_cursor;
  std::sort(views.begin(), views.end());
  if (pending) *pending = left_out;
  return views;
}

void ViewChangeTracker::markAll(const core::SelectionOutput& snapshot) {
  const size_t n = snapshot.size();
  sent_.resize(n);
  for (size_t i = 0; i < n; ++i) sent_[i] = record(snapshot, i);
  cursor_ = 0;
}

void SelectionOutputs::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const InputStatistics::Counts counts = statistics_.counts();
  const ros::WallTime now = ros::WallTime::now();
  double rate = 0.0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    received_.emplace_back(now, counts.frames_received);
    while (received_.size() > 2 && (now - received_.front().first).toSec() > kRateWindow)
      received_.pop_front();
    const double span = (received_.back().first - received_.front().first).toSec();
    if (span > 0.0 && received_.back().second >= received_.front().second)
      rate = static_cast<double>(received_.back().second - received_.front().second) / span;
  }
  double lag = 0.0;
  const size_t pending = worker_.pending(&lag);
  const size_t keyframes = worker_.served()->selection.size();

  if (lag > kLagWarning)
    status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN,
                    "worker %.1f s behind (%zu frames waiting)", lag, pending);
  else if (counts.frames_received == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "waiting for frames");
  else
    status.summaryf(diagnostic_msgs::DiagnosticStatus::OK, "%zu keyframes, %.1f frames/s",
                    keyframes, rate);
  status.add("input rate [frames/s]", rate);
  status.add("frames received", counts.frames_received);
  status.add("frames offered", counts.frames_offered);
  status.add("frames dropped", counts.dropped_total());
  status.add("time jumps", counts.time_jumps);
  for (const auto& [reason, count] : counts.dropped) status.add("dropped: " + reason, count);
  status.add("frames waiting for the worker", pending);
  status.add("worker lag [s]", lag);
  status.add("keyframes", keyframes);
  status.add("revisits (no keyframe)", counts.revisits);
  status.add("revisits recognised from the image", counts.revisits_registered);
  status.add("last insertion [s]", counts.last_insertion_seconds);
  status.add("max insertion [s]", counts.max_insertion_seconds);
  status.add("since last keyframe [s]",
             counts.last_insertion.isZero() ? -1.0 : (now - counts.last_insertion).toSec());
  if (!counts.last_error.empty()) status.add("last error", counts.last_error);
}

}  // namespace view_selection::ros_node
