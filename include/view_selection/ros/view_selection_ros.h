// view_selection_node and the view_selection/ViewSelectionNodelet: the parts of the node, each
// in a file of its own, composed in the order data flows (docs/architecture.md):
//   inputs (image, camera_info, depth; map points) -> worker (pose, core::ViewSelector) ->
//   served selection -> outputs (~selection, ~markers, ~statistics, /diagnostics) and services.
// Members are built in that order and torn down in reverse, so no callback ever reaches a part
// that is gone, and a constructor that throws leaves no thread running (every part joins its
// threads in its destructor).
#pragma once

#include "view_selection/ros/frame_inputs.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_image_writer.h"
#include "view_selection/ros/keyframe_verdicts.h"
#include "view_selection/ros/keyframe_worker.h"
#include "view_selection/ros/live_reconfigure.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/pair_stream.h"
#include "view_selection/ros/path_corrections.h"
#include "view_selection/ros/pose_provider.h"
#include "view_selection/ros/selection_outputs.h"
#include "view_selection/ros/selection_services.h"
#include "view_selection/ros/state_keeper.h"

#include <ros/ros.h>

#include <memory>

namespace view_selection::ros_node {

class ViewSelectionRos {
 public:
  /// Reads the ~parameters (throws core::InvalidArgument naming a bad one), subscribes to the
  /// relative topics on `nh`, advertises outputs and services on `private_nh`.
  ViewSelectionRos(ros::NodeHandle nh, ros::NodeHandle private_nh,
                   const PointSourceFactory& make_points = {});
  ViewSelectionRos(const ViewSelectionRos&) = delete;
  ViewSelectionRos& operator=(const ViewSelectionRos&) = delete;

 private:
  const NodeConfig config_;
  InputStatistics statistics_;
  StateKeeper keeper_;  // before the worker, which saves through it until it is gone
  std::unique_ptr<PoseProvider> poses_;
  KeyframeVerdicts verdicts_;
  PairStream pairs_;                 // fed by the worker
  KeyframeImageWriter image_writer_;  // fed by the worker
  KeyframeWorker worker_;
  SelectionOutputs outputs_;
  SelectionServices services_;
  LiveReconfigure reconfigure_;
  PathCorrections corrections_;
  FrameInputs inputs_;  // last: no frame arrives before every other part exists
};

}  // namespace view_selection::ros_node
