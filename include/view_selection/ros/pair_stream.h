// The pair stream: the selection's pairs announced to a consumer that matches them while the
// camera still moves (colmap_bridge, docs/live.md). The worker hands it the pairs that appeared
// and went after each change of the selection; it applies the stability rule
// (core::PairAnnouncer, ~pair_stable_keyframes), numbers what it announces, publishes it on
// ~pairs and keeps the last ~pair_history messages for ~get_pairs. When no frame arrived for
// ~pair_flush_idle seconds it announces every pending pair (the recording paused or ended) in a
// `flushed` message, sent once a pause even when nothing was pending: that the frames stopped
// is what tells colmap_bridge to finish (keyframes alone pause whenever the camera walks where
// it has been). Its own lock only: the worker calls it under the state lock, services and the
// timer never wait for an insertion.
#pragma once

#include "view_selection/core/pair_announcer.h"
#include "view_selection/core/selection_output.h"
#include "view_selection/ros/node_config.h"

#include <ros/ros.h>
#include <view_selection/GetPairs.h>
#include <view_selection/PairChanges.h>

#include <atomic>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>

namespace view_selection::ros_node {

class PairStream {
 public:
  /// Advertises ~pairs on `private_nh`; with ~pair_flush_idle > 0, a wall timer on its queue.
  PairStream(const NodeConfig& config, ros::NodeHandle private_nh);

  /// The worker, after the selection changed: `changes` (ViewSelector::takePairChanges) and the
  /// output they belong to. Publishes a message when pairs were announced or keyframes came.
  void update(const core::PairChanges& changes, const core::SelectionOutput& output);
  /// A new session (~reset, a time jump): nothing is announced; a full, empty message follows.
  void reset(const core::SelectionOutput& output);
  /// A session continued from ~state_file: its pairs count as announced, the sequence continues
  /// after `sequence`; a full message follows.
  void restore(uint64_t sequence, const core::SelectionOutput& output);
  /// A frame arrived or was handled (for ~pair_flush_idle).
  void frameSeen() {
    last_frame_ns_ = ros::WallTime::now().toNSec();
    pause_told_ = false;
  }
  /// Announces every pending pair now (the timer does when no frame came for a while).
  void flush();

  uint64_t sequence() const;
  /// ~get_pairs.
  void answer(uint64_t since, view_selection::GetPairs::Response& res) const;

 private:
  using MessagePtr = view_selection::PairChangesPtr;
  /// Under mutex_: numbers, keeps and publishes a message of `announced` with the keyframes new
  /// since the last message and those the pairs name.
  void emitLocked(const core::Announcement& announced, bool full, bool flushed);
  view_selection::PairChanges fullMessageLocked() const;
  void onTimer(const ros::WallTimerEvent&);

  const NodeConfig& config_;
  ros::Publisher publisher_;
  ros::WallTimer timer_;
  std::atomic<uint64_t> last_frame_ns_{0};
  std::atomic<bool> pause_told_{false};  ///< a flushed message went out since the last frame

  mutable std::mutex mutex_;
  core::PairAnnouncer announcer_;
  core::SelectionOutput output_;  ///< the last one handed over (its chunks are shared)
  uint64_t sequence_ = 0;
  uint64_t first_kept_ = 1;       ///< the oldest sequence in history_ (or the next one)
  uint64_t session_start_ = 1;    ///< messages before it belong to an earlier session
  std::size_t keyframes_listed_ = 0;  ///< keyframes named in a message so far
  std::deque<MessagePtr> history_;
};

}  // namespace view_selection::ros_node
