// What the node did with its input: frames received, offered, dropped by reason, insertion
// times. Thread-safe; every drop is counted and logged, throttled per reason. Counts belong to a
// session (a ~reset starts the next): the outcome of a frame received in an earlier session is
// not counted in the current one, so frames_offered + frame drops never exceed frames_received.
#pragma once

#include "view_selection/session/session_state.h"

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
    /// Frames paired on a timeout before a nearer partner was ruled out (timing decided them).
    uint64_t frames_paired_on_timeout = 0;
    uint64_t paths_applied = 0;           ///< loop-closure paths applied
    uint64_t keyframes_corrected = 0;     ///< keyframe pose corrections, over all paths
    uint64_t frames_offered = 0;
    uint64_t keyframes = 0;  ///< offered frames that became keyframes
    uint64_t revisits = 0;   ///< offered frames the revisit rule kept from becoming keyframes
    uint64_t revisits_registered = 0;  ///< ... of them, recognised from their image
    uint64_t time_jumps = 0;  ///< times stamps went back and a new session started (since ~reset)
    std::map<std::string, uint64_t> dropped;
    std::string last_error;
    ros::Time last_error_stamp;
    ros::Time last_frame_stamp;  ///< of the last frame offered or dropped (zero: none)
    double last_insertion_seconds = 0.0;
    double max_insertion_seconds = 0.0;
    ros::WallTime last_insertion;  ///< when the last keyframe was inserted (zero: none yet)
    uint64_t dropped_total() const;
    /// Drops of frames (all reasons but "bad_map", which counts map clouds).
    uint64_t frames_dropped() const;
  };

  /// An offered frame became no keyframe because an earlier keyframe has its view (the revisit
  /// rule), found by registering its image or not.
  void revisit(uint64_t session, bool registered);
  /// A message reached the subscriber callback of one of the synchroniser's inputs.
  void arrived(Input input);
  /// How many images the synchroniser holds now (the last of a bag waits for a later partner).
  void setImagesInSynchroniser(uint64_t images);
  /// `frames` were paired on a timeout, before a nearer partner was ruled out.
  void pairedOnTimeout(uint64_t frames);
  /// A loop-closure path was applied and moved `keyframes` keyframes.
  void pathApplied(uint64_t keyframes);
  /// A synchronised frame reached the node; returns the session it belongs to.
  uint64_t frameReceived();
  /// A valid frame of `session` was offered to the keyframe policy; `insertion_seconds` >= 0
  /// when it became a keyframe (points + matrix time).
  void frameOffered(uint64_t session, const ros::Time& stamp, double insertion_seconds);
  /// A frame of `session` was dropped: counted under `reason` (unless the session is over),
  /// logged as a warning at most once per `kLogPeriod` per reason (with the number not logged).
  void drop(uint64_t session, const std::string& reason, const std::string& message,
            const ros::Time& stamp);
  /// Something other than a received frame (a map cloud, a path, an image that never became a
  /// frame) was dropped: counted and logged the same way.
  void dropInput(const std::string& reason, const std::string& message, const ros::Time& stamp);
  /// Starts a new session with zero counts.
  void reset();
  /// Starts a new session after a time jump: zero counts but time_jumps, which counts it.
  void timeJump();
  uint64_t session() const;

  /// The counts as a saved session keeps them: frames_received counts only the frames handled
  /// (offered or dropped), so that a replay after last_frame_stamp re-sends exactly the others.
  session::SessionStatistics toSaved() const;
  /// Continues from saved counts (a new session) of a session with `keyframes` keyframes.
  void restore(const session::SessionStatistics& saved, uint64_t keyframes);
  /// ~state_file: the last state written had `keyframes` keyframes and its last frame handled
  /// at `frame_stamp`.
  void stateSaved(uint32_t keyframes, const ros::Time& frame_stamp);

  Counts counts() const;
  /// Bumps on every change.
  uint64_t version() const;
  /// The ~statistics message, stamped with ROS time (simulated during replays).
  view_selection::InputStatistics toMsg() const;

  static constexpr double kLogPeriod = 5.0;  ///< [s, wall] between warnings of one reason
  /// Frames the node stopped before it could handle them (no pose yet at shutdown).
  static constexpr const char* kShutdownReason = "shutdown";

 private:
  struct Throttle {
    ros::WallTime last;
    uint64_t suppressed = 0;
  };
  /// Counts a drop: of a frame of `session` (ignored when that session is over), or of another
  /// input (null).
  void count(const std::string& reason, const std::string& message, const ros::Time& stamp,
             const uint64_t* session);
  mutable std::mutex mutex_;
  Counts counts_;
  uint64_t session_ = 0;
  uint64_t version_ = 0;
  uint32_t saved_keyframes_ = 0;
  ros::Time saved_frame_stamp_;
  std::map<std::string, Throttle> throttle_;
};

/// A stamp as "1305031102.175304" (6 decimals), for log lines and messages.
std::string stampText(const ros::Time& stamp);

}  // namespace view_selection::ros_node
