// The node's services: ~get_next_views, ~get_selection, ~export, ~reset and ~save_state. They
// answer from the worker's last snapshot on callback queues and threads of their own, so an
// insertion never holds up an answer; the file writers (~export, ~save_state) have a queue and
// thread apart from the queries, so a long export never holds up ~get_selection either.
#pragma once

#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_image_writer.h"
#include "view_selection/ros/keyframe_worker.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/pair_stream.h"
#include "view_selection/ros/pose_provider.h"
#include "view_selection/ros/state_keeper.h"

#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <view_selection/Export.h>
#include <view_selection/GetNextViews.h>
#include <view_selection/GetPairs.h>
#include <view_selection/GetSelection.h>
#include <view_selection/WriteKeyframeImages.h>

#include <functional>

namespace view_selection::ros_node {

class SelectionServices {
 public:
  /// `on_reset` runs after a reset (e.g. to publish the empty selection at once).
  SelectionServices(const NodeConfig& config, ros::NodeHandle private_nh, KeyframeWorker& worker,
                    PoseProvider& poses, StateKeeper& keeper, PairStream& pairs,
                    KeyframeImageWriter& image_writer, std::function<void()> on_reset);
  ~SelectionServices();

  /// The callback queue the services run on (shared with dynamic_reconfigure's).
  ros::CallbackQueue& queue() { return queue_; }
  /// [s] ~save_state answers with the result when the save is on disk within this, else that it
  /// is under way (the worker and the state keeper do the work; this thread only waits).
  static constexpr double kSaveAnswerWait = 10.0;

 private:
  bool getNextViews(view_selection::GetNextViews::Request& req,
                    view_selection::GetNextViews::Response& res);
  bool getSelection(view_selection::GetSelection::Request& req,
                    view_selection::GetSelection::Response& res);
  bool exportSelection(view_selection::Export::Request& req, view_selection::Export::Response& res);
  bool reset(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool saveState(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool getPairs(view_selection::GetPairs::Request& req, view_selection::GetPairs::Response& res);
  bool writeImages(view_selection::WriteKeyframeImages::Request& req,
                   view_selection::WriteKeyframeImages::Response& res);

  const NodeConfig& config_;
  KeyframeWorker& worker_;
  PoseProvider& poses_;
  StateKeeper& keeper_;
  PairStream& pairs_;
  KeyframeImageWriter& image_writer_;
  std::function<void()> on_reset_;
  ros::CallbackQueue queue_, files_queue_;
  ros::ServiceServer next_views_, selection_, export_, reset_, save_state_, get_pairs_,
      write_images_;
  ros::AsyncSpinner spinner_, files_spinner_;
};

/// Writes the snapshot's keyframe images under the names pairs.txt uses, into `directory`.
/// Returns how many; throws core::IoError naming the image that could not be written.
int writeKeyframeImages(const std::string& directory, const ServedSelection& served);

}  // namespace view_selection::ros_node
