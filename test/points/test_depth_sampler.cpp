// Depth conversion, grid sampling with one robust point per cell, and the occlusion depth map.
#include "view_selection/points/depth_sampler.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/occlusion_map.h"
#include "view_selection/images/image_conversion.h"

#include "support/box_depth.h"
#include "support/test_support.h"

#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include "support/layers.h"

namespace view_selection {
namespace {

// The tests hold depth as cv::Mat; the sampler and the occlusion map read core views of it.
Eigen::Matrix3Xd sampleDepthPoints(const cv::Mat& depth, const PinholeIntrinsics& k,
                                   const CameraPose& pose, const DepthSamplerConfig& config) {
  return points::sampleDepthPoints(depthImageOf(depth), k, pose, config);
}
DepthMap downsampleDepth(const cv::Mat& depth, const PinholeIntrinsics& k, int cell) {
  return makeOcclusionMap(depthImageOf(depth), k, cell);
}

using test::lookAt;
using test::vgaIntrinsics;

TEST(DepthSampler, ConvertsEncodingsToMetres) {
  cv::Mat mm(2, 2, CV_16UC1);
  mm.at<uint16_t>(0, 0) = 0;
  mm.at<uint16_t>(0, 1) = 1500;
  mm.at<uint16_t>(1, 0) = 5000;
  mm.at<uint16_t>(1, 1) = 65535;
  const cv::Mat m = depthToMetres(mm, 0.001);
  ASSERT_EQ(m.type(), CV_32FC1);
  EXPECT_EQ(m.at<float>(0, 0), 0.0f);
  EXPECT_FLOAT_EQ(m.at<float>(0, 1), 1.5f);
  EXPECT_FLOAT_EQ(depthToMetres(mm, 1.0 / 5000.0).at<float>(1, 0), 1.0f);

  cv::Mat f(1, 4, CV_32FC1);
  f.at<float>(0, 0) = std::nanf("");
  f.at<float>(0, 1) = -1.0f;
  f.at<float>(0, 2) = INFINITY;
  f.at<float>(0, 3) = 2.25f;
  const cv::Mat g = depthToMetres(f, 1.0);
  EXPECT_EQ(g.at<float>(0, 0), 0.0f);
  EXPECT_EQ(g.at<float>(0, 1), 0.0f);
  EXPECT_EQ(g.at<float>(0, 2), 0.0f);
  EXPECT_EQ(g.at<float>(0, 3), 2.25f);

  EXPECT_THROW(depthToMetres(cv::Mat(), 1.0), InvalidInput);
  EXPECT_THROW(depthToMetres(cv::Mat(2, 2, CV_8UC1, cv::Scalar(3)), 1.0), InvalidInput);
  EXPECT_THROW(depthToMetres(cv::Mat(2, 2, CV_16UC3), 1.0), InvalidInput);
  EXPECT_THROW(depthToMetres(mm, 0.0), InvalidArgument);
}

TEST(DepthSampler, OnePointPerCellOnTheTrueSurface) {
  const PinholeIntrinsics k = vgaIntrinsics();
  const CameraPose pose = lookAt({0.3, -0.2, 0.1}, {1.0, 0.4, 2.0}, 0.2);
  const Eigen::Vector3d half(2.0, 1.5, 2.5);
  const cv::Mat depth = test::renderBoxDepth(k, pose, half);
  DepthSamplerConfig config;
  const Eigen::Matrix3Xd points = sampleDepthPoints(depth, k, pose, config);
  ASSERT_EQ(points.cols(), config.grid * config.grid);
  for (Eigen::Index c = 0; c < points.cols(); ++c) {
    // On a wall: one coordinate at +-half, the others inside.
    const Eigen::Vector3d p = points.col(c);
    const double on_wall = (p.cwiseAbs() - half).cwiseAbs().minCoeff();
    EXPECT_LT(on_wall, 1e-5 * 3.0) << p.transpose();
    EXPECT_TRUE(((p.cwiseAbs() - half).array() < 1e-4).all());
    // And in front of the camera, inside its own image.
    const Eigen::Vector3d pc = pose.worldToCamera(p);
    EXPECT_GT(pc.z(), 0.0);
    EXPECT_TRUE(k.inImage(k.project(pc)));
  }
  // A smaller depth image of the same camera gives points on the same walls.
  cv::Mat half_size;
  cv::resize(depth, half_size, {320, 240}, 0, 0, cv::INTER_NEAREST);
  const Eigen::Matrix3Xd coarse = sampleDepthPoints(half_size, k, pose, config);
  ASSERT_EQ(coarse.cols(), 256);
  for (Eigen::Index c = 0; c < coarse.cols(); ++c)
    EXPECT_LT((coarse.col(c).cwiseAbs() - half).cwiseAbs().minCoeff(), 0.02);
}

TEST(DepthSampler, SkipsEmptyCellsAndIgnoresOutliers) {
  const PinholeIntrinsics k = vgaIntrinsics();
  CameraPose pose;  // identity: camera frame = world frame
  cv::Mat depth(480, 640, CV_32FC1, cv::Scalar(2.0f));
  depth.colRange(0, 320).setTo(0.0f);  // left half missing
  // Top-right cell: 10 % of its pixels are a near spike; the median ignores them.
  const cv::Rect cell(600, 0, 40, 30);
  for (int v = cell.y; v < cell.y + cell.height; ++v)
    for (int u = cell.x; u < cell.x + 4; ++u) depth.at<float>(v, u) = 0.5f;
  DepthSamplerConfig config;
  config.pixel_stride = 1;
  const Eigen::Matrix3Xd points = sampleDepthPoints(depth, k, pose, config);
  ASSERT_EQ(points.cols(), 128);
  for (Eigen::Index c = 0; c < points.cols(); ++c) {
    EXPECT_FLOAT_EQ(points(2, c), 2.0);
    EXPECT_GT(points(0, c), -1e-9);  // right half only
  }
  // A cell with too few valid pixels gives nothing.
  cv::Mat sparse(480, 640, CV_32FC1, cv::Scalar(0.0f));
  for (int v = 0; v < 30; v += 4) sparse.at<float>(v, 5) = 1.0f;  // 8 of 1200 pixels in cell 0
  EXPECT_EQ(sampleDepthPoints(sparse, k, pose, config).cols(), 0);
  config.min_valid_fraction = 0.0;
  EXPECT_EQ(sampleDepthPoints(sparse, k, pose, config).cols(), 1);
  // Depth outside [min_depth, max_depth] is missing.
  cv::Mat far(480, 640, CV_32FC1, cv::Scalar(12.0f));
  EXPECT_EQ(sampleDepthPoints(far, k, pose, DepthSamplerConfig{}).cols(), 0);
  EXPECT_THROW(sampleDepthPoints(cv::Mat(4, 4, CV_16UC1), k, pose, config), InvalidInput);
}

TEST(DepthSampler, DownsampledMapHoldsCellMedians) {
  PinholeIntrinsics k = vgaIntrinsics();
  cv::Mat depth(480, 640, CV_32FC1, cv::Scalar(3.0f));
  depth(cv::Rect(0, 0, 8, 8)).setTo(0.0f);  // cell (0, 0) unknown
  depth(cv::Rect(8, 0, 8, 8)).setTo(1.0f);  // cell (1, 0) at 1 m ...
  depth(cv::Rect(8, 0, 2, 8)).setTo(9.0f);  // ... with a 25 % spike
  const DepthMap map = downsampleDepth(depth, k, 8);
  EXPECT_EQ(map.cols, 80);
  EXPECT_EQ(map.rows, 60);
  EXPECT_EQ(map.at(3.0, 3.0), 0.0f);
  EXPECT_EQ(map.at(12.0, 4.0), 1.0f);
  EXPECT_EQ(map.at(639.9, 479.9), 3.0f);
  EXPECT_EQ(map.at(-1.0, 4.0), 0.0f);
  // A half-size depth image maps onto the same full-resolution cells.
  cv::Mat small;
  cv::resize(depth, small, {320, 240}, 0, 0, cv::INTER_NEAREST);
  const DepthMap coarse = downsampleDepth(small, k, 8);
  EXPECT_EQ(coarse.cols, 80);
  EXPECT_EQ(coarse.at(639.9, 479.9), 3.0f);
}

}  // namespace
}  // namespace view_selection
