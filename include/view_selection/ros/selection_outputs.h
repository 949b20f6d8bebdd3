// What the node publishes: the latched ~selection, ~markers and ~statistics when they change (at
// most every ~publish_period), and /diagnostics through diagnostic_updater.
#pragma once

#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_worker.h"
#include "view_selection/ros/node_config.h"

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include <cstdint>
#include <deque>
#include <mutex>
#include <utility>

namespace view_selection::ros_node {

class SelectionOutputs {
 public:
  SelectionOutputs(const NodeConfig& config, ros::NodeHandle nh, ros::NodeHandle private_nh,
                   const KeyframeWorker& worker, const InputStatistics& statistics);
  ~SelectionOutputs();

  /// Publishes what changed since the last call (the timer calls this).
  void update();
  /// A new ~publish_period [s, wall] (dynamic_reconfigure).
  void setPublishPeriod(double seconds);

 private:
  static constexpr double kMinPeriod = 0.02;         ///< [s] fastest publishing
  static constexpr double kDiagnosticsPeriod = 1.0;  ///< [s] /diagnostics
  static constexpr double kRateWindow = 10.0;        ///< [s, wall] input rate averaged over
  static constexpr double kLagWarning = 2.0;         ///< [s] oldest waiting frame: WARN beyond

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  const NodeConfig& config_;
  const KeyframeWorker& worker_;
  const InputStatistics& statistics_;
  ros::Publisher selection_pub_, markers_pub_, statistics_pub_;
  ros::WallTimer timer_, diagnostics_timer_;
  diagnostic_updater::Updater diagnostics_;
  uint64_t published_version_ = 0;
  uint64_t published_stats_version_ = ~uint64_t{0};
  std::mutex mutex_;  // update() may run on two threads (timer, reconfigure)
  std::deque<std::pair<ros::WallTime, uint64_t>> received_;  // for the input rate
};

}  // namespace view_selection::ros_node
