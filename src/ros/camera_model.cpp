#include "view_selection/ros/camera_model.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/ros/conversions.h"

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/image_encodings.h>

#include <opencv2/imgproc.hpp>

#include <cmath>
#include <sstream>

namespace view_selection::ros_node {

namespace {
bool anyNonZero(const std::vector<double>& d) {
  for (double v : d)
    if (v != 0.0) return true;
  return false;
}
}  // namespace

CameraModel cameraModelFromInfo(const sensor_msgs::CameraInfo& info) {
  CameraModel camera;
  camera.intrinsics = intrinsicsFromCameraInfo(info);  // K's checks and messages
  camera.rectify = anyNonZero(info.D);
  const bool binned = info.binning_x > 1 || info.binning_y > 1;
  const bool roi = info.roi.width > 0 && info.roi.height > 0 &&
                   (info.roi.width != info.width || info.roi.height != info.height ||
                    info.roi.x_offset != 0 || info.roi.y_offset != 0);
  if (!camera.rectify && !binned && !roi) return camera;
  if (camera.rectify && info.distortion_model != "plumb_bob" &&
      info.distortion_model != "rational_polynomial" && info.distortion_model != "equidistant")
    throw core::InvalidInput("camera_info distortion model '" + info.distortion_model +
                             "' with non-zero D cannot be undone (plumb_bob, rational_polynomial, "
                             "equidistant); the images would be used distorted");
  try {
    if (!camera.model.fromCameraInfo(info))
      throw core::InvalidInput("image_geometry rejected the camera_info");
  } catch (const image_geometry::Exception& e) {
    throw core::InvalidInput(std::string("image_geometry rejected the camera_info: ") + e.what());
  }
  const cv::Size size = camera.model.reducedResolution();
  core::PinholeIntrinsics k;
  if (camera.rectify) {  // the rectified image's projection
    k.fx = camera.model.fx();
    k.fy = camera.model.fy();
    k.cx = camera.model.cx();
    k.cy = camera.model.cy();
  } else {  // K, scaled for binning and shifted for the ROI
    const cv::Matx33d& km = camera.model.intrinsicMatrix();
    k.fx = km(0, 0);
    k.fy = km(1, 1);
    k.cx = km(0, 2);
    k.cy = km(1, 2);
  }
  k.width = size.width;
  k.height = size.height;
  if (!k.isValid() || !std::isfinite(k.cx) || !std::isfinite(k.cy)) {
    std::ostringstream s;
    s << "camera_info " << (camera.rectify ? "P (the rectified projection)" : "K with binning/ROI")
      << " is unusable: fx=" << k.fx << " fy=" << k.fy << ", size " << k.width << "x" << k.height;
    throw core::InvalidInput(s.str());
  }
  camera.intrinsics = k;
  return camera;
}

cv::Mat rectifiedImage(const CameraModel& camera, const cv::Mat& image) {
  cv::Mat out;
  camera.model.rectifyImage(image, out, cv::INTER_LINEAR);
  return out;
}

sensor_msgs::ImageConstPtr rectifiedImageMessage(const CameraModel& camera,
                                                 const sensor_msgs::ImageConstPtr& image) {
  namespace enc = sensor_msgs::image_encodings;
  const cv_bridge::CvImageConstPtr in = enc::isBayer(image->encoding)
                                            ? cv_bridge::toCvCopy(image, enc::BGR8)
                                            : cv_bridge::toCvShare(image);
  return cv_bridge::CvImage(image->header, in->encoding, rectifiedImage(camera, in->image))
      .toImageMsg();
}

cv::Mat rectifiedDepth(const CameraModel& camera, const cv::Mat& depth) {
  cv::Mat out;
  camera.model.rectifyImage(depth, out, cv::INTER_NEAREST);
  return out;
}

}  // namespace view_selection::ros_node
