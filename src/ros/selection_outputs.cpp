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
  selection_pub_ = private_nh.advertise<view_selection::ViewSelection>("selection", 1, true);
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
  const std::shared_ptr<const NodeSnapshot> snapshot = worker_.snapshot();
  if (snapshot->version != published_version_) {
    selection_pub_.publish(selectionToMsg(snapshot->selection, config_.world_frame));
    markers_pub_.publish(
        selectionMarkers(snapshot->selection, config_.world_frame, config_.marker_scale));
    published_version_ = snapshot->version;
  }
  const uint64_t stats_version = statistics_.version();
  if (stats_version != published_stats_version_) {
    statistics_pub_.publish(statistics_.toMsg());
    published_stats_version_ = stats_version;
  }
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
  const size_t keyframes = worker_.snapshot()->selection.size();

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
  for (const auto& [reason, count] : counts.dropped) status.add("dropped: " + reason, count);
  status.add("frames waiting for the worker", pending);
  status.add("worker lag [s]", lag);
  status.add("keyframes", keyframes);
  status.add("last insertion [s]", counts.last_insertion_seconds);
  status.add("max insertion [s]", counts.max_insertion_seconds);
  status.add("since last keyframe [s]",
             counts.last_insertion.isZero() ? -1.0 : (now - counts.last_insertion).toSec());
  if (!counts.last_error.empty()) status.add("last error", counts.last_error);
}

}  // namespace view_selection::ros_node
