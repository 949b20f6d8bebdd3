// dynamic_reconfigure for what is cheap to change while the node runs (cfg/ViewSelection.cfg): k
// and completion (the selection is redone), the gates (the matrix is recomputed), the keyframe
// thresholds and ~publish_period.
#pragma once

#include "view_selection/ros/keyframe_worker.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/selection_outputs.h"

#include <dynamic_reconfigure/server.h>
#include <ros/ros.h>
#include <view_selection/ViewSelectionConfig.h>

#include <boost/thread/recursive_mutex.hpp>

namespace view_selection::ros_node {

/// The dynamic_reconfigure values of `config` (and back): one mapping for both directions.
view_selection::ViewSelectionConfig toReconfigure(const NodeConfig& config);
void fromReconfigure(const view_selection::ViewSelectionConfig& values, NodeConfig& config);

class LiveReconfigure {
 public:
  /// Serves ~set_parameters on `private_nh` (whose callback queue it uses), starting from the
  /// values in force, `config`.
  LiveReconfigure(const NodeConfig& config, ros::NodeHandle private_nh, KeyframeWorker& worker,
                  SelectionOutputs& outputs);

 private:
  void onChange(view_selection::ViewSelectionConfig& values, uint32_t level);

  NodeConfig current_;  // the values in force, changed by onChange only
  KeyframeWorker& worker_;
  SelectionOutputs& outputs_;
  boost::recursive_mutex mutex_;
  dynamic_reconfigure::Server<view_selection::ViewSelectionConfig> server_;
};

}  // namespace view_selection::ros_node
