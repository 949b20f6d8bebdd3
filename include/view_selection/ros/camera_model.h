// The camera as camera_info describes it, read with image_geometry: binning and ROI honoured (the
// intrinsics and size of the image as it arrives), and distortion applied, not ignored: an image
// with non-zero distortion coefficients is rectified (colour bilinear, depth nearest, so no depth
// is invented between surfaces) and takes the rectified intrinsics, P.
#pragma once

#include "view_selection/core/types.h"

#include <image_geometry/pinhole_camera_model.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <opencv2/core.hpp>

namespace view_selection::ros_node {

struct CameraModel {
  core::PinholeIntrinsics intrinsics;  ///< of the image the core sees (rectified when distorted)
  bool rectify = false;                ///< distortion coefficients are not all zero
  image_geometry::PinholeCameraModel model;
};

/// Throws core::InvalidInput with the reason: unusable K (zero, negative or non-finite focal
/// lengths, zero size), a distortion model image_geometry cannot undo, an unusable P for a
/// distorted camera, or a binning/ROI image_geometry rejects. A camera without distortion,
/// binning or ROI gets K as it is (what select_views uses for a TUM folder).
CameraModel cameraModelFromInfo(const sensor_msgs::CameraInfo& info);
/// The rectified image (same type); `image` must have the size camera_info gives.
cv::Mat rectifiedImage(const CameraModel& camera, const cv::Mat& image);
/// The image message rectified (a Bayer mosaic debayered to bgr8 first, since interpolating a
/// mosaic mixes its colours), same header; what an export writes for a distorted camera, so that
/// the images agree with the intrinsics it writes.
sensor_msgs::ImageConstPtr rectifiedImageMessage(const CameraModel& camera,
                                                 const sensor_msgs::ImageConstPtr& image);
/// The rectified depth (CV_32FC1 metres, 0 = none), nearest neighbour.
cv::Mat rectifiedDepth(const CameraModel& camera, const cv::Mat& depth);

}  // namespace view_selection::ros_node
