// The worker: frames from the inputs wait in a bounded queue; one thread looks up each frame's
// pose, converts it and hands it to the core's ViewSelector, which keeps the keyframes and the
// matrix. After a change it shares an immutable ServedSelection, which services and outputs read
// without waiting for an insertion. Nothing waits for the worker: the inputs queue frames under
// the queue lock alone, ~reset and reconfigures are handed to the worker's thread and return at
// once, and a ServedSelection costs O(what changed) (core::SelectionOutput shares its chunks).
#pragma once

#include "view_selection/core/pose_correction.h"
#include "view_selection/core/selection_output.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/ros/camera_model.h"
#include "view_selection/ros/image_cache.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_image_writer.h"
#include "view_selection/ros/keyframe_verdicts.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/pair_stream.h"
#include "view_selection/ros/pose_provider.h"
#include "view_selection/ros/state_keeper.h"

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

namespace view_selection::ros_node {

/// One synchronised frame as it arrived.
struct PendingFrame {
  sensor_msgs::ImageConstPtr image;
  sensor_msgs::CameraInfoConstPtr info;
  sensor_msgs::ImageConstPtr depth;  ///< null without depth
  /// The worker's generation() when the image arrived: a frame of an earlier one (a ~reset or a
  /// time jump since) is discarded by push(), so it never enters the new session.
  uint64_t generation = 0;
};

/// What services and publishers read: the selection and, with ~save_keyframe_images, the
/// keyframe images. Immutable once shared.
struct ServedSelection {
  uint64_t version = 0;  ///< bumps with every change
  core::SelectionOutput selection;
  /// By keyframe id, ids below image_count (null without ~save_keyframe_images); RAM-bounded.
  std::shared_ptr<const KeyframeImageCache> images;
  size_t image_count = 0;
};

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
  /// Stops the thread (a frame in flight is abandoned: it is not part of the saved session),
  /// joins it, and saves the session when it changed since the last save.
  ~KeyframeWorker();
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
  /// The whole session now, for ~save_state (copied under the state lock, written outside it).
  StateSnapshot captureState();
  /// Replaces the map of the "map" point source and recomputes the rows of the keyframes whose
  /// points changed. Throws core::InvalidInput for bad points (nothing changes then).
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
  /// recomputed and a new snapshot published. Returns how many moved.
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
  struct Queued {
    PendingFrame frame;
    uint64_t generation = 0;  ///< reset() count when it was queued
    uint64_t session = 0;     ///< its statistics session
    ros::WallTime queued;
  };

  void loop();
  /// Before the next frame: a ~reset or reconfigure handed over since. Takes the state lock.
  void applyRequests();
  void process(const Queued& queued);
  /// Checks and converts a frame; false (after counting the drop) when it is unusable.
  bool convert(const Queued& queued, CameraModel& camera);
  /// Under state_mutex_: shares the selector's state with readers (unless a reset happened since
  /// the state's generation began).
  void shareSelectionLocked();
  /// Under state_mutex_, after a keyframe: shares now, or leaves it for later while frames wait.
  void keyframeInsertedLocked();
  /// Installs `next` as the served selection, unless `generation` is over; the old one is
  /// released outside the lock.
  void installServed(std::shared_ptr<ServedSelection> next, uint64_t generation);
  /// Under state_mutex_: clears the selector for reset() generation `generation` (after
  /// handing the old session to the keeper when a time jump ended it).
  void applyResetLocked(uint64_t generation);
  /// reset() and timeJump(): a new generation and statistics session, the queue emptied, an
  /// empty selection served. Returns the number of keyframes forgotten.
  size_t startSession(bool time_jump);
  /// Under state_mutex_: the session for the state file.
  StateSnapshot captureStateLocked();
  /// What changed since the last capture, for the state journal (O(changed) but the version scan).
  JournalSnapshot captureDeltaLocked();
  /// At construction: continues the session the keeper read, or starts empty.
  void restoreLoaded();
  void drop(const Queued& queued, const std::string& reason, const std::string& message);
  std::shared_ptr<KeyframeImageCache> newImageCache() const;

  const NodeConfig& config_;
  PoseProvider& poses_;
  InputStatistics& statistics_;
  StateKeeper& keeper_;
  KeyframeVerdicts* verdicts_;
  PairStream* pairs_;
  KeyframeImageWriter* image_writer_;

  // The method's state, guarded by state_mutex_ (timed: servedLatest() waits only so long).
  mutable std::timed_mutex state_mutex_;
  std::unique_ptr<core::ViewSelector> selector_;
  std::shared_ptr<ImageFolder> image_folder_;    // with ~save_keyframe_images: ~image_dir
  std::shared_ptr<KeyframeImageCache> images_;  // by keyframe id; a new one after each reset
  std::optional<double> last_stamp_;                // of the last frame offered to the core
  std::string camera_frame_;                        // the images' frame_id, normalised
  uint64_t applied_generation_ = 0;  // the generation selector_ belongs to
  uint64_t captures_ = 0;            // state snapshots taken (their sequence)
  int keyframes_since_save_ = 0;     // towards ~autosave_keyframes
  io::DeltaTracker saved_;           // what the last capture held (state lock)
  std::atomic<bool> changed_since_save_{false};  // anything a saved session would differ in
  std::atomic<bool> unshared_{false};  // keyframes inserted and not yet shared
  std::atomic<size_t> keyframe_count_{0};  // keyframes accepted in this generation
  std::atomic<size_t> queued_count_{0};    // queue_.size(), read without the queue lock
  ros::WallTime last_share_;

  // Bumps on reset() (under queue_mutex_ and served_mutex_); frames and shares of an older
  // generation are discarded.
  std::atomic<uint64_t> generation_{0};

  mutable std::mutex served_mutex_;
  std::shared_ptr<const ServedSelection> served_;
  uint64_t version_ = 0;  // of served_; guarded by served_mutex_

  // A time jump's old session, to be kept in <state_file>.previous when the worker clears it:
  // the generation it belonged to and its statistics at the jump. The first one pending wins.
  struct Aside {
    uint64_t generation = 0;
    io::SessionStatistics statistics;
  };
  std::mutex aside_mutex_;
  std::optional<Aside> aside_;

  mutable std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<Queued> queue_;
  std::optional<core::ViewSelectorConfig> pending_config_;  // reconfigure() not yet applied
  bool stopping_ = false;
  std::thread thread_;  // last: started when everything above exists
};

}  // namespace view_selection::ros_node
