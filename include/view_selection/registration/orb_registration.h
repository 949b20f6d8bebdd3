// core::FrameRegistration with OpenCV: ORB features of each keyframe kept with their 3D points
// from its depth; a frame is registered to a keyframe by matching its ORB features to them
// (nearest neighbour, ratio test) and a RANSAC PnP. The revisit rule asks it when the poses
// found no earlier keyframe that has a frame's view (docs/design.md, "Revisits under drift").
#pragma once

#include "view_selection/core/frame_registration.h"

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

namespace view_selection::registration {

struct OrbRegistrationConfig {
  int features = 500;                ///< ORB features detected per image
  /// FAST's corner threshold (OpenCV's default 20): 10 finds enough corners on small or soft
  /// images (on the odometry's 10 minutes of a walk at 160 x 120, 59% of the frames asked
  /// registered at 20, 99.6% at 10).
  int fast_threshold = 10;
  double ratio = 0.8;                ///< nearest / second-nearest Hamming distance, at most
  int min_inliers = 40;              ///< PnP inliers for a registration
  double min_inlier_share = 0.4;     ///< of the ratio test's matches
  double max_reprojection_px = 2.0;  ///< RANSAC threshold; the inliers' RMS must be under half
  int ransac_iterations = 200;
};

class OrbRegistration : public core::FrameRegistration {
 public:
  explicit OrbRegistration(OrbRegistrationConfig config = {});

  void keyframeAdded(core::ViewId id, const core::Frame& frame) override;
  std::optional<core::CameraPose> relativePose(const core::Frame& frame, core::ViewId id) override;
  /// By the zero-mean, unit-norm thumbnails (kThumbnailWidth x kThumbnailHeight, blurred) of the
  /// images: the largest correlation first.
  std::vector<core::ViewId> alikeKeyframes(const core::Frame& frame, core::ViewId below,
                                           std::size_t max) override;
  static constexpr int kThumbnailWidth = 32;
  static constexpr int kThumbnailHeight = 24;
  void clear() override;

  /// A keyframe's descriptors, their points and its thumbnail. restoreKept refuses bytes that
  /// are truncated, of another descriptor or thumbnail size, or with points not in front.
  std::vector<uint8_t> keptBytes(core::ViewId id) const override;
  bool restoreKept(core::ViewId id, const std::vector<uint8_t>& bytes) override;

  /// Keyframes with features kept, and their bytes (descriptors and points).
  std::size_t keyframesKept() const;
  std::size_t bytes() const;
  /// relativePose calls that reached a keyframe with features, and those that registered.
  std::size_t attempts() const { return attempts_; }
  std::size_t registrations() const { return registrations_; }

 private:
  struct Features {
    std::vector<cv::KeyPoint> keypoints;
    cv::Mat descriptors;  // CV_8U, one row per keypoint
    cv::Mat thumbnail;    // CV_32F, one row, zero mean and unit norm
  };
  struct Kept {
    cv::Mat descriptors;              // rows with a valid depth only
    std::vector<cv::Point3f> points;  // in the keyframe's camera frame
  };
  /// The frame's features, detected once per frame (by stamp) however many keyframes it is
  /// registered to; none without an image or without a keypoint.
  const Features* frameFeatures(const core::Frame& frame);
  /// Detects the frame's features and thumbnail into cached_.
  void detect(const core::Frame& frame);
  /// Room for keyframe `id` in kept_ and thumbnails_, its entries emptied.
  void makeRoom(core::ViewId id);

  OrbRegistrationConfig config_;
  cv::Ptr<cv::Feature2D> orb_;
  std::vector<Kept> kept_;  // by keyframe id
  cv::Mat thumbnails_;      // row id: keyframe id's thumbnail (zeros: none kept)
  std::optional<double> cached_stamp_;
  Features cached_;  // of the frame at cached_stamp_
  std::size_t attempts_ = 0;
  std::size_t registrations_ = 0;
};

}  // namespace view_selection::registration
