// A SLAM stand-in that drifts like a real one (issue 29): OpenCV's dense RGB-D visual odometry
// (cv::rgbd, Debian's OpenCV contrib) chaining frame-to-keyframe (or frame-to-frame) motions into
// camera poses, with no pose input, no loop closure and no global optimisation. Its error
// accumulates: this is odometry, not ground truth. A frame it cannot track (a blank image, no
// valid depth, a motion it cannot explain) gets no pose and is counted; after a run of them it
// starts again from its last pose (a jump, counted), as real front ends re-initialise.
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstdint>
#include <memory>
#include <string>

namespace view_selection::odometry {

struct OdometryConfig {
  /// rgbd: photometric and depth (cv::rgbd::RgbdOdometry); icp: depth only (ICPOdometry);
  /// rgbd_icp: both (RgbdICPOdometry).
  std::string method = "rgbd";
  /// frame: each frame against the one before (the default: it drifts most, as the issue's
  /// measurement of OpenCV's frame-to-frame odometry did); keyframe: each frame against the last
  /// reference keyframe, a new one after keyframe_translation or keyframe_rotation_deg of motion.
  std::string reference = "frame";
  double keyframe_translation = 0.10;   ///< [m]
  double keyframe_rotation_deg = 10.0;  ///< [deg]
  double min_depth = 0.3;               ///< [m] depth outside [min, max] is not used
  double max_depth = 4.0;               ///< [m]
  double max_depth_difference = 0.07;   ///< [m] correspondences further apart in depth are rejected
  /// [m] and [deg] between the reference and the current frame: a larger result is a failure.
  double max_translation = 0.3;
  double max_rotation_deg = 30.0;
  /// A frame is unusable with fewer valid depth pixels than this fraction, or a grey-level
  /// standard deviation below min_contrast (a blank or covered camera).
  double min_valid_depth = 0.05;
  double min_contrast = 2.0;  ///< [grey levels]
  /// After this many frames lost in a row, the next usable frame becomes the reference at the
  /// last pose (the motion while lost is lost: a jump).
  int restart_after_lost = 10;
  /// Track on images made smaller by a whole factor until at most this wide (0: full size).
  /// 320, the default, tracks a 640x480 camera at 320x240: 8 ms a frame instead of 33 on this
  /// project's 2-core machine, so that it keeps up at 30 Hz beside the node and COLMAP, and
  /// drifts more, as a front end on a small budget does; a 320x240 camera is tracked as it is.
  int max_width = 320;

  /// Throws core::InvalidArgument naming the bad value.
  void validate() const;
};

struct OdometryResult {
  enum class Status { kInitialised, kTracked, kLost, kRestarted };
  Status status = Status::kLost;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< camera-to-odom (optical frame); not for kLost
  bool new_keyframe = false;
  std::string reason;  ///< why a frame was lost, in words
};

const char* statusName(OdometryResult::Status status);

struct OdometryCounts {
  uint64_t frames = 0, tracked = 0, lost = 0, restarts = 0, keyframes = 0;
};

class RgbdOdometryTracker {
 public:
  explicit RgbdOdometryTracker(const OdometryConfig& config = {});
  ~RgbdOdometryTracker();
  RgbdOdometryTracker(const RgbdOdometryTracker&) = delete;
  RgbdOdometryTracker& operator=(const RgbdOdometryTracker&) = delete;

  /// One frame at `stamp` [s]: grey (CV_8UC1) or colour (CV_8UC3, BGR) image, depth CV_32FC1 in
  /// metres (0 or NaN: none), same size; the intrinsics of both (registered depth). The motion
  /// since the last tracked frame, scaled to the time since, is the starting guess (a constant
  /// velocity). Throws core::InvalidInput for sizes or types it cannot take (a caller's
  /// mistake, not tracking).
  OdometryResult track(double stamp, const cv::Mat& image, const cv::Mat& depth,
                       const core::PinholeIntrinsics& intrinsics);

  /// Starts over at the identity (a new session).
  void reset();

  const OdometryCounts& counts() const { return counts_; }
  const OdometryConfig& config() const { return config_; }

 private:
  struct Impl;
  OdometryConfig config_;
  OdometryCounts counts_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace view_selection::odometry
