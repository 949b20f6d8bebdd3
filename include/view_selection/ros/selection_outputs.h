// What the node publishes: the latched ~selection, ~markers and ~statistics when they change (at
// most every ~publish_period), and /diagnostics through diagnostic_updater. Above
// ~publish_max_views keyframes ~selection carries only the views that changed (bounded) and
// ~markers a summary (docs/node.md, "Large maps").
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
#include <vector>

namespace view_selection::ros_node {

/// What a subscriber of ~selection has been sent of each view, to find the views that are new or
/// changed since: a view's keyframe (stamp, pose, number of points) or its next view set (the
/// ids before and after completion, and its row's version, which covers the E values).
class ViewChangeTracker {
 public:
  /// The views (ascending from where the last call stopped, wrapping round, so none starves) that
  /// differ from what was sent, at most `limit`; they count as sent from now on. `pending` gets
  /// how many differing views were left out.
  std::vector<core::ViewId> take(const core::SelectionOutput& snapshot, size_t limit,
                                 size_t* pending);
  /// Every view counts as sent (after a message with the whole selection).
  void markAll(const core::SelectionOutput& snapshot);

 private:
  struct Sent {
    bool valid = false;  ///< false: never sent
    double stamp = 0.0;
    std::size_t num_points = 0;
    core::CameraPose pose;
    std::size_t selected = 0;          ///< |C_i| before completion
    std::vector<core::ViewId> final;   ///< C_i after completion
    std::uint64_t row_version = 0;
  };
  static bool same(const Sent& sent, const core::SelectionOutput& snapshot, size_t i);
  static Sent record(const core::SelectionOutput& snapshot, size_t i);

  std::vector<Sent> sent_;  ///< by view id
  size_t cursor_ = 0;       ///< where the next take() starts
};

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
  static constexpr uint32_t kSelectionQueue = 100;   ///< ~selection messages a subscriber may lag
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
  uint64_t updates_ = 0;          // messages on ~selection
  size_t pending_views_ = 0;      // changed views a bounded message left out
  ViewChangeTracker tracker_;
  uint64_t published_stats_version_ = ~uint64_t{0};
  std::mutex mutex_;  // update() may run on two threads (timer, reconfigure)
  std::deque<std::pair<ros::WallTime, uint64_t>> received_;  // for the input rate
};

}  // namespace view_selection::ros_node
