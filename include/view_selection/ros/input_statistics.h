// What the node did with its input: frames received, offered, dropped by reason, insertion
// times. Thread-safe; every drop is counted and logged, throttled per reason.
#pragma once

#include <ros/time.h>
#include <view_selection/InputStatistics.h>

#include <cstdint>
#include <map>
#include <mutex>
#include <string>

namespace view_selection::ros_node {

class InputStatistics {
 public:
  /// The synchroniser's inputs, counted as they arrive.
  enum class Input { kImage, kCameraInfo, kDepth };

  struct Counts {
    uint64_t images_arrived = 0;
    uint64_t camera_infos_arrived = 0;
    uint64_t depths_arrived = 0;
    uint64_t frames_received = 0;
    uint64_t images_in_synchroniser = 0;  ///< arrived, neither output nor discarded yet
    uint64_t paths_applied = 0;           ///< loop-closure paths applied
    uint64_t keyframes_corrected = 0;     ///< keyframe pose corrections, over all paths
    uint64_t frames_offered = 0;
    std::map<std::string, uint64_t> dropped;
    std::string last_error;
    ros::Time last_error_stamp;
    double last_insertion_seconds = 0.0;
    double max_insertion_seconds = 0.0;
    ros::WallTime last_insertion;  ///< when the last keyframe was inserted (zero: none yet)
    uint64_t dropped_total() const;
  };

  /// A message reached the subscriber callback of one of the synchroniser's inputs.
  void arrived(Input input);
  /// How many images the synchroniser holds now (the last of a bag waits for a later partner).
  void setImagesInSynchroniser(uint64_t images);
  /// A loop-closure path was applied and moved `keyframes` keyframes.
  void pathApplied(uint64_t keyframes);
  /// A synchronised frame reached the node.
  void frameReceived();
  /// A valid frame was offered to the keyframe policy; `insertion_seconds` >= 0 when it became a
  /// keyframe (points + matrix time).
  void frameOffered(double insertion_seconds);
  /// A frame (or a map) was dropped: counted under `reason`, logged as a warning at most once per
  /// `kLogPeriod` per reason (with the number not logged since).
  void drop(const std::string& reason, const std::string& message, const ros::Time& stamp);
  void reset();

  Counts counts() const;
  /// Bumps on every change.
  uint64_t version() const;
  /// The ~statistics message, stamped with ROS time (simulated during replays).
  view_selection::InputStatistics toMsg(uint32_t keyframes) const;

  static constexpr double kLogPeriod = 5.0;  ///< [s, wall] between warnings of one reason

 private:
  struct Throttle {
    ros::WallTime last;
    uint64_t suppressed = 0;
  };
  mutable std::mutex mutex_;
  Counts counts_;
  uint64_t version_ = 0;
  std::map<std::string, Throttle> throttle_;
};

/// A stamp as "1305031102.175304" (6 decimals), for log lines and messages.
std::string stampText(const ros::Time& stamp);

}  // namespace view_selection::ros_node
