// The worker: one thread takes each frame the inputs queued, looks up its pose, converts it and
// hands it to the core's ViewSelector, which keeps the keyframes and the matrix; after a change
// it shares an immutable ServedSelection, which services and outputs read without waiting for an
// insertion. Its parts, each in a file of its own with the lock it takes:
//   intake            ros/frame_queue       the queue lock: frames and the requests other
//                                            threads hand over (~reset, time jumps, reconfigures)
//   checks            ros/frame_checks      no lock: a frame's messages and camera model
//   insertion         here                  the state lock: the selector, pose corrections, map
//                                            points; the waits for a pose or a verdict hold none
//   sharing           ros/served_selection  the served lock: the selection readers get
//   persistence       ros/session_handoff   under the state lock (and the aside lock): what
//                                            the state keeper's thread writes
//   image output      ros/keyframe_images   under the state lock: the image cache for ~export,
//                                            the keyframe image writer's thread
//   registration log  session/registration_log  under the state lock: what the revisit
//                                            rule's registration keeps of the keyframes, for a
//                                            restart
// Nothing waits for the worker: the inputs queue frames under the queue lock alone, ~reset and
// reconfigures are handed to the worker's thread and return at once, and a ServedSelection costs
// O(what changed) (core::SelectionOutput shares its chunks). Locks nest queue > aside and
// queue > served (a new generation), state > served (a share) and state > aside (a time jump's
// session handed over); the state lock is never taken under the queue lock or the served lock.
#pragma once

#include "view_selection/core/pose_correction.h"
#include "view_selection/core/selection_output.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/ros/frame_queue.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_image_writer.h"
#include "view_selection/ros/keyframe_images.h"
#include "view_selection/ros/keyframe_verdicts.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/pair_stream.h"
#include "view_selection/ros/pose_provider.h"
#include "view_selection/ros/served_selection.h"
#include "view_selection/ros/session_handoff.h"
#include "view_selection/ros/state_keeper.h"
#include "view_selection/session/registration_log.h"

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

namespace view_selection::ros_node {

/// Makes the worker's point source from the node's configuration (points::makePointSource by
/// default; tests pass another, e.g. a deliberately slow one).
using PointSourceFactory = std::function<std::unique_ptr<core::PointSource>(const NodeConfig&)>;

class KeyframeWorker {
 public:
  /// Makes the selector (throws core::InvalidArgument for bad parameters), continues the
  /// session `keeper` read (when it can; otherwise the keeper sets the file aside and the
  /// session starts empty) and starts the thread. `verdicts`: the external keyframe decisions
  /// (~keyframe_policy external), or null. `pairs`: the pair stream fed after every change of
  /// the selection, or null. `image_writer`: where accepted keyframes' images go, or null.
  KeyframeWorker(const NodeConfig& config, PoseProvider& poses, InputStatistics& statistics,
                 StateKeeper& keeper, KeyframeVerdicts* verdicts = nullptr,
                 const PointSourceFactory& make_points = {}, PairStream* pairs = nullptr,
                 KeyframeImageWriter* image_writer = nullptr);
  /// Stops taking frames, handles the frames still queued (none waits for a pose or a verdict
  /// any more: one whose pose has not come is a kShutdownDrop), joins the thread, and saves the
  /// session when it changed since the last save (the state keeper writes what still waits).
  ~KeyframeWorker();
  /// The drop reason of a frame whose pose or verdict had not come when the node stopped. Such a
  /// frame does not move the statistics' last frame stamp: a replay after a restart from the
  /// state file sends it again.
  static constexpr const char* kShutdownDrop = InputStatistics::kShutdownReason;
  KeyframeWorker(const KeyframeWorker&) = delete;
  KeyframeWorker& operator=(const KeyframeWorker&) = delete;

  /// Queues a frame (under the queue lock only: never waits for an insertion); when
  /// ~max_pending_frames wait already, the oldest is dropped ("worker_behind").
  void push(PendingFrame frame);
  /// Forgets every keyframe and waiting frame (and the external keyframe verdicts) and starts a
  /// new statistics session, at once: the served selection is empty when it returns. A frame in
  /// flight is discarded, not inserted, and not counted in the new session; the worker's thread
  /// clears the selector before its next frame and saves the empty session (so that a crash
  /// after a reset does not bring back the old one). Returns the number of keyframes forgotten.
  size_t reset();
  /// Time went back from `newest` to `stamp` (more than ~time_jump_threshold): a new session
  /// starts as with reset(), the jump is logged and counted (time_jumps), the pose source and
  /// the keyframe verdicts start a new timeline, and with ~state_file the old session is written
  /// to `<state_file>.previous` first (by the keeper's thread).
  void timeJump(const ros::Time& newest, const ros::Time& stamp);
  /// Bumps on every reset() and timeJump(); frames of an earlier one are discarded by push().
  uint64_t generation() const { return generation_.load(); }
  /// The last stamp offered to the core (continued from ~state_file: its last frame's), if any.
  std::optional<double> lastStamp() const;
  /// ~save_state: the whole session is captured on the worker's thread before its next frame
  /// and written by the state keeper's; `done` runs on the keeper's thread with the result (at
  /// once when saving is off). Returns at once: no caller waits for the state lock.
  void requestSave(std::function<void(const SaveResult&)> done);
  /// Replaces the map of the "map" point source: the worker's thread applies it before its next
  /// frame and recomputes the rows of the keyframes whose points changed (the caller, an input
  /// callback, never waits for that). Throws core::InvalidInput for non-finite points.
  void setMapPoints(Eigen::Matrix3Xd points);
  /// New method parameters, live, applied by the worker's thread before its next frame (this
  /// returns at once; readers keep the served selection until the new one is shared): the
  /// selection is redone; the matrix is recomputed when its gates changed; the keyframe policy
  /// keeps its place. `config` must be valid (validate() first).
  void reconfigure(const core::ViewSelectorConfig& config);
  /// Loop closure: each keyframe takes `corrections` (world-frame changes at the path's stamps,
  /// core::pathCorrections) applied to the pose the source gave it (`sourcePose` at its stamp;
  /// its current pose when the history has none, e.g. continued from ~state_file), when that
  /// moves it more than the thresholds (core::matchCorrections); their rows and columns are
  /// recomputed and a new snapshot published. With ~correct_later_frames the frames that come
  /// next take the same corrections (after the path's last stamp, its last one), until the next
  /// path or reset. Returns how many moved.
  size_t correctPoses(const std::vector<core::TimedPose>& corrections,
                      const std::function<std::optional<core::CameraPose>(double)>& sourcePose,
                      const core::PoseCorrectionConfig& config);
  /// The (normalised) frame_id of the images so far; "" before the first.
  std::string cameraFrame() const;

  /// The selection shared last; never null, never waits.
  std::shared_ptr<const ServedSelection> served() const;
  /// The selection with every keyframe accepted so far: shares it first when keyframes were
  /// inserted since (while frames wait the worker coalesces its shares), waiting at most
  /// kLatestWait for the state lock (then the last shared one). For services.
  std::shared_ptr<const ServedSelection> servedLatest();
  static constexpr double kLatestWait = 0.05;  ///< [s]
  /// While frames wait, the worker shares at least this often [s].
  static constexpr double kMaxShareInterval = 0.1;
  /// Frames waiting, and how long the oldest has waited [s, wall].
  size_t pending(double* oldest_age = nullptr) const;

 private:
  void loop();
  /// Before the next frame: a ~reset or reconfigure handed over since. Takes the state lock.
  void applyRequests();
  void process(const QueuedFrame& queued);
  /// Under state_mutex_: shares the selector's state with readers (unless a reset happened since
  /// the state's generation began).
  void shareSelectionLocked();
  /// Under state_mutex_, after a keyframe: shares now, or leaves it for later while frames wait.
  void keyframeInsertedLocked();
  /// Under state_mutex_: clears the selector for reset() generation `generation` (after
  /// handing the old session to the keeper when a time jump ended it).
  void applyResetLocked(uint64_t generation);
  /// reset() and timeJump(): a new generation and statistics session, the queue emptied, an
  /// empty selection served. Returns the number of keyframes forgotten.
  size_t startSession(bool time_jump);
  /// Under state_mutex_: the map handed over by setMapPoints.
  void applyMapLocked(Eigen::Matrix3Xd points);
  /// At construction: continues the session the keeper read, or starts empty.
  void restoreLoaded();
  /// Under state_mutex_: the registration log emptied for a new session, or read back for a
  /// continued one; what went wrong logged.
  void startRegistrationLog(bool continued);
  void drop(const QueuedFrame& queued, const std::string& reason, const std::string& message);

  const NodeConfig& config_;
  PoseProvider& poses_;
  InputStatistics& statistics_;
  StateKeeper& keeper_;
  KeyframeVerdicts* verdicts_;
  PairStream* pairs_;

  // Bumps on reset() and timeJump(), under the queue lock and the served lock; frames and
  // shares of an older generation are discarded.
  std::atomic<uint64_t> generation_{0};

  // The method's state, guarded by state_mutex_ (timed: servedLatest() waits only so long).
  mutable std::timed_mutex state_mutex_;
  std::unique_ptr<core::ViewSelector> selector_;  // made first: bad parameters throw here
  std::optional<double> last_stamp_;  // of the last frame offered to the core
  // ~correct_later_frames: the corrections of the newest path (ascending stamp; empty before one,
  // and after a reset); each frame's pose takes them as a keyframe's does (core::correctedPose).
  std::vector<core::TimedPose> later_corrections_;
  std::string camera_frame_;          // the images' frame_id, normalised
  uint64_t applied_generation_ = 0;   // the generation selector_ belongs to
  std::atomic<bool> unshared_{false};      // keyframes inserted and not yet shared
  std::atomic<size_t> keyframe_count_{0};  // keyframes accepted in this generation
  ros::WallTime last_share_;

  // The parts, each with its own lock or under the state lock (see the top of this file).
  FrameQueue intake_;        // the queue lock
  SharedSelection shared_;   // the served lock
  SessionHandoff handoff_;   // under the state lock; the aside lock
  KeyframeImages images_;    // under the state lock
  session::RegistrationLog registration_log_;  // under the state lock

  std::thread thread_;  // last: started when everything above exists
};

}  // namespace view_selection::ros_node
