// camera_info read with image_geometry (no master): binning, ROI, distortion applied.
#include "view_selection/ros/camera_model.h"

#include "view_selection/core/exceptions.h"

#include <cv_bridge/cv_bridge.h>
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

namespace view_selection::ros_node {
namespace {

sensor_msgs::CameraInfo info(const std::vector<double>& d = {0, 0, 0, 0, 0},
                             const std::string& model = "plumb_bob") {
  sensor_msgs::CameraInfo c;
  c.width = 640;
  c.height = 480;
  c.distortion_model = model;
  c.D = d;
  c.K = {525.0, 0.0, 319.5, 0.0, 520.0, 239.5, 0.0, 0.0, 1.0};
  c.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  c.P = {500.0, 0.0, 320.0, 0.0, 0.0, 500.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0};
  return c;
}

TEST(CameraModel, WithoutDistortionBinningOrRoiKIsTakenAsItIs) {
  const CameraModel c = cameraModelFromInfo(info());
  EXPECT_FALSE(c.rectify);
  EXPECT_EQ(c.intrinsics.fx, 525.0);
  EXPECT_EQ(c.intrinsics.fy, 520.0);
  EXPECT_EQ(c.intrinsics.cx, 319.5);
  EXPECT_EQ(c.intrinsics.width, 640);
  // Zeros under another model name are no distortion either.
  EXPECT_FALSE(
      cameraModelFromInfo(info(std::vector<double>(8, 0.0), "rational_polynomial")).rectify);
}

TEST(CameraModel, BinningAndRoiAreHonoured) {
  sensor_msgs::CameraInfo binned = info();
  binned.binning_x = binned.binning_y = 2;
  const CameraModel b = cameraModelFromInfo(binned);
  EXPECT_NEAR(b.intrinsics.fx, 525.0 / 2, 1e-9);
  EXPECT_NEAR(b.intrinsics.fy, 520.0 / 2, 1e-9);
  EXPECT_NEAR(b.intrinsics.cx, 319.5 / 2, 1e-9);
  EXPECT_EQ(b.intrinsics.width, 320);
  EXPECT_EQ(b.intrinsics.height, 240);
  sensor_msgs::CameraInfo roi = info();
  roi.roi.x_offset = 100;
  roi.roi.y_offset = 50;
  roi.roi.width = 320;
  roi.roi.height = 240;
  const CameraModel r = cameraModelFromInfo(roi);
  EXPECT_NEAR(r.intrinsics.fx, 525.0, 1e-9);
  EXPECT_NEAR(r.intrinsics.cx, 319.5 - 100, 1e-9);
  EXPECT_NEAR(r.intrinsics.cy, 239.5 - 50, 1e-9);
  EXPECT_EQ(r.intrinsics.width, 320);
  EXPECT_EQ(r.intrinsics.height, 240);
}

TEST(CameraModel, DistortedImagesAreRectifiedToP) {
  const CameraModel c = cameraModelFromInfo(info({-0.25, 0.08, 0.0, 0.0, 0.0}));
  ASSERT_TRUE(c.rectify);
  EXPECT_EQ(c.intrinsics.fx, 500.0);
  EXPECT_EQ(c.intrinsics.cx, 320.0);
  // A dot where the lens put the point that the rectified image shows at (560, 420).
  const cv::Point2d rect(560.0, 420.0);
  const cv::Point2d raw = c.model.unrectifyPoint(rect);
  ASSERT_GT(cv::norm(raw - rect), 10.0) << "the test needs visible distortion there";
  cv::Mat image(480, 640, CV_8UC1, cv::Scalar(0));
  cv::circle(image, cv::Point(cvRound(raw.x), cvRound(raw.y)), 2, cv::Scalar(255), cv::FILLED);
  double peak = 0.0;
  cv::Point at;
  cv::minMaxLoc(rectifiedImage(c, image), nullptr, &peak, nullptr, &at);
  EXPECT_GT(peak, 100.0);
  EXPECT_LT(cv::norm(cv::Point2d(at) - rect), 2.0) << at;
  // Depth: nearest neighbour, so only the values that were there.
  cv::Mat depth(480, 640, CV_32FC1, cv::Scalar(0.0f));
  cv::circle(depth, cv::Point(cvRound(raw.x), cvRound(raw.y)), 3, cv::Scalar(2.0f), cv::FILLED);
  const cv::Mat d = rectifiedDepth(c, depth);
  EXPECT_FLOAT_EQ(d.at<float>(cvRound(rect.y), cvRound(rect.x)), 2.0f);
  const cv::Mat other = (d != 0.0f) & (d != 2.0f);
  EXPECT_EQ(cv::countNonZero(other), 0) << "rectified depth holds blended values";
}

TEST(CameraModel, RectifiedMessagesKeepHeaderAndEncoding) {
  const CameraModel c = cameraModelFromInfo(info({-0.25, 0.08, 0.0, 0.0, 0.0}));
  cv::Mat image(480, 640, CV_8UC3, cv::Scalar(0, 0, 0));
  const cv::Point2d rect(560.0, 420.0);
  const cv::Point2d raw = c.model.unrectifyPoint(rect);
  cv::circle(image, cv::Point(cvRound(raw.x), cvRound(raw.y)), 2, cv::Scalar(0, 0, 255), cv::FILLED);
  std_msgs::Header h;
  h.stamp = ros::Time(12.5);
  h.frame_id = "cam";
  const auto msg = cv_bridge::CvImage(h, "rgb8", image).toImageMsg();
  const sensor_msgs::ImageConstPtr out = rectifiedImageMessage(c, msg);
  EXPECT_EQ(out->header.stamp, h.stamp);
  EXPECT_EQ(out->header.frame_id, "cam");
  EXPECT_EQ(out->encoding, "rgb8");
  ASSERT_EQ(out->width, 640u);
  const cv::Mat back = cv_bridge::toCvShare(out)->image;
  std::vector<cv::Mat> channels;
  cv::split(back, channels);
  double peak = 0.0;
  cv::Point at;
  cv::minMaxLoc(channels[2], nullptr, &peak, nullptr, &at);
  EXPECT_GT(peak, 100.0);
  EXPECT_LT(cv::norm(cv::Point2d(at) - rect), 2.0) << at;
}

TEST(CameraModel, UnusableCamerasAreRejectedWithTheReason) {
  try {
    cameraModelFromInfo(info({0.1, 0.0, 0.0, 0.0}, "kannala_brandt_custom"));
    FAIL() << "an unknown distortion model with non-zero D must not pass";
  } catch (const core::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("cannot be undone"), std::string::npos) << e.what();
  }
  sensor_msgs::CameraInfo no_p = info({-0.2, 0.0, 0.0, 0.0, 0.0});
  no_p.P.fill(0.0);
  EXPECT_THROW(cameraModelFromInfo(no_p), core::InvalidInput);
  sensor_msgs::CameraInfo zero = info();
  zero.K[0] = 0.0;
  EXPECT_THROW(cameraModelFromInfo(zero), core::InvalidInput);
}

}  // namespace
}  // namespace view_selection::ros_node
