// The worker: frames from the inputs wait in a bounded queue; one thread looks up each frame's
// pose, converts it and hands it to the core's ViewSelector, which keeps the keyframes and the
// matrix. After every change it publishes an immutable snapshot, which services and outputs read
// without waiting for an insertion.
#pragma once

#include "view_selection/core/pose_correction.h"
#include "view_selection/core/selection_snapshot.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/ros/camera_model.h"
#include "view_selection/ros/image_cache.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_verdicts.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/pose_provider.h"
#include "view_selection/ros/state_keeper.h"

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace view_selection::ros_node {

/// One synchronised frame as it arrived.
struct PendingFrame {
  sensor_msgs::ImageConstPtr image;
  sensor_msgs::CameraInfoConstPtr info;
  sensor_msgs::ImageConstPtr depth;  ///< null without depth
};

/// What readers see: the selection and, with ~save_keyframe_images, the keyframe images.
struct NodeSnapshot {
  uint64_t version = 0;  ///< bumps with every change
  core::SelectionSnapshot selection;
  /// By keyframe id, ids below image_count (null without ~save_keyframe_images); RAM-bounded.
  std::shared_ptr<const KeyframeImageCache> images;
  size_t image_count = 0;
};

class KeyframeWorker {
 public:
  /// Makes the selector (throws core::InvalidArgument for bad parameters), continues the
  /// session `keeper` read (when it can; otherwise the keeper sets the file aside and the
  /// session starts empty) and starts the thread. `verdicts`: the external keyframe decisions
  /// (~keyframe_policy external), or null.
  KeyframeWorker(const NodeConfig& config, PoseProvider& poses, InputStatistics& statistics,
                 StateKeeper& keeper, KeyframeVerdicts* verdicts = nullptr);
  /// Stops the thread (a frame in flight is abandoned: it is not part of the saved session),
  /// joins it, and saves the session when it changed since the last save.
  ~KeyframeWorker();
  KeyframeWorker(const KeyframeWorker&) = delete;
  KeyframeWorker& operator=(const KeyframeWorker&) = delete;

  /// Queues a frame; when ~max_pending_frames wait already, the oldest is dropped
  /// ("worker_behind").
  void push(PendingFrame frame);
  /// Forgets every keyframe and waiting frame and starts a new statistics session; a frame in
  /// flight is discarded, not inserted, and not counted in the new session. Saves the empty
  /// session (so that a crash after a reset does not bring back the old one). Returns the number
  /// of keyframes forgotten.
  size_t reset();
  /// The whole session now, for ~save_state (copied under the state lock, written outside it).
  StateSnapshot captureState();
  /// Replaces the map of the "map" point source and recomputes the rows of the keyframes whose
  /// points changed. Throws core::InvalidInput for bad points (nothing changes then).
  void setMapPoints(Eigen::Matrix3Xd points);
  /// New method parameters, live: the selection is redone; the matrix is recomputed when its
  /// gates changed; the keyframe policy keeps its place.
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

  /// The last snapshot; never null.
  std::shared_ptr<const NodeSnapshot> snapshot() const;
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
  void process(const Queued& queued);
  /// Checks and converts a frame; false (after counting the drop) when it is unusable.
  bool convert(const Queued& queued, CameraModel& camera);
  /// Under state_mutex_: a new snapshot of the selector's state.
  void publishSnapshotLocked();
  /// Under state_mutex_: the session for the state file.
  StateSnapshot captureStateLocked();
  /// At construction: continues the session the keeper read, or starts empty.
  void restoreLoaded();
  void drop(const Queued& queued, const std::string& reason, const std::string& message);
  std::shared_ptr<KeyframeImageCache> newImageCache() const;

  const NodeConfig& config_;
  PoseProvider& poses_;
  InputStatistics& statistics_;
  StateKeeper& keeper_;
  KeyframeVerdicts* verdicts_;

  // The method's state, guarded by state_mutex_.
  mutable std::mutex state_mutex_;
  std::unique_ptr<core::ViewSelector> selector_;
  std::shared_ptr<ImageFolder> image_folder_;    // with ~save_keyframe_images: ~image_dir
  std::shared_ptr<KeyframeImageCache> images_;  // by keyframe id; a new one after each reset
  std::optional<double> last_stamp_;                // of the last frame offered to the core
  std::string camera_frame_;                        // the images' frame_id, normalised
  uint64_t generation_ = 0;  // bumps on reset(); frames of older ones are discarded
  uint64_t version_ = 0;
  uint64_t captures_ = 0;            // state snapshots taken (their sequence)
  int keyframes_since_save_ = 0;     // towards ~autosave_keyframes
  bool changed_since_save_ = false;  // anything a saved session would differ in

  mutable std::mutex snapshot_mutex_;
  std::shared_ptr<const NodeSnapshot> snapshot_;

  mutable std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<Queued> queue_;
  bool stopping_ = false;
  std::thread thread_;  // last: started when everything above exists
};

}  // namespace view_selection::ros_node
