// The worker's intake: frames from the inputs wait here, bounded, for the worker's thread, with
// the requests other threads hand to it (a ~reset or time jump, a reconfigure). Everything here
// happens under the queue lock alone, so the inputs never wait for an insertion. The frames'
// statistics session is counted under the same lock (a frame belongs to exactly one session).
#pragma once

#include "view_selection/core/view_selector.h"
#include "view_selection/ros/input_statistics.h"

#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
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

/// A frame in the queue.
struct QueuedFrame {
  PendingFrame frame;
  uint64_t generation = 0;  ///< the generation when it was queued
  uint64_t session = 0;     ///< its statistics session
  ros::WallTime queued;
};

class FrameQueue {
 public:
  /// At most `capacity` frames wait (~max_pending_frames). `generation` is the worker's session
  /// generation: read here under the queue lock; bumped (by the worker, through
  /// startGeneration) while the queue lock is held.
  FrameQueue(size_t capacity, InputStatistics& statistics,
             const std::atomic<uint64_t>& generation);

  /// What push() did.
  struct Pushed {
    bool queued = false;                ///< false: stopping, or a frame of an earlier generation
    std::optional<QueuedFrame> overflow;  ///< the oldest frame, pushed out (count it dropped)
  };
  /// Queues a frame and counts it received; the oldest waiting frame makes room when `capacity`
  /// wait already.
  Pushed push(PendingFrame frame);
  /// Frames waiting, and how long the oldest has waited [s, wall].
  size_t pending(double* oldest_age = nullptr) const;
  /// queue size, read without the queue lock.
  size_t queuedCount() const { return queued_count_.load(); }

  /// A new generation (~reset, a time jump): under the queue lock, the waiting frames are
  /// forgotten and `under_lock` runs (it bumps the generation and starts the new statistics
  /// session); then the worker's thread is woken.
  void startGeneration(const std::function<void()>& under_lock);
  /// New method parameters for the worker's thread (the latest one wins).
  void reconfigure(const core::ViewSelectorConfig& config);
  /// A new map for the "map" point source, applied by the worker's thread (a later one replaces
  /// one not taken yet: each map replaces the last anyway).
  void setMap(Eigen::Matrix3Xd points);
  /// ~save_state: `save` runs on the worker's thread before its next frame (it captures the
  /// session there, so that no service thread waits for the state lock).
  void requestSave(std::function<void()> save);

  /// What other threads handed the worker's thread since it last asked.
  struct Requests {
    uint64_t generation = 0;  ///< the generation now
    std::optional<core::ViewSelectorConfig> config;
    std::optional<Eigen::Matrix3Xd> map;
    std::vector<std::function<void()>> saves;
  };
  /// For the worker's thread: the requests handed over since the last call, and the generation
  /// now, read together under the queue lock.
  Requests takeRequests();

  /// For the worker's thread: the next frame, waiting for one. When the queue is empty, `idle`
  /// runs first (without the queue lock). Returns without a frame when a request is waiting
  /// (a reconfigure, or a generation other than `applied_generation`): apply it and call again;
  /// `*stop` turns true after stop(), once every frame queued before it was returned.
  std::optional<QueuedFrame> next(uint64_t applied_generation, const std::function<void()>& idle,
                                  bool* stop);
  /// Wakes the worker's thread for good: push() queues nothing more, next() returns the frames
  /// still queued (nothing accepted is lost at shutdown), then sets `*stop`.
  void stop();
  /// Whether stop() was called.
  bool stopping() const;

 private:
  const size_t capacity_;
  InputStatistics& statistics_;
  const std::atomic<uint64_t>& generation_;

  mutable std::mutex mutex_;  // the queue lock
  std::condition_variable wake_;
  std::deque<QueuedFrame> queue_;
  std::atomic<size_t> queued_count_{0};  // queue_.size()
  std::optional<core::ViewSelectorConfig> pending_config_;  // reconfigure() not yet taken
  std::optional<Eigen::Matrix3Xd> pending_map_;             // setMap() not yet taken
  std::vector<std::function<void()>> pending_saves_;        // requestSave() not yet taken
  bool stopping_ = false;
};

}  // namespace view_selection::ros_node
