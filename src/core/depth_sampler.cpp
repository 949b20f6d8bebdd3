#include "view_selection/core/depth_sampler.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace view_selection {

void DepthSamplerConfig::validate() const {
  if (grid_cols < 1 || grid_rows < 1)
    throw InvalidArgument("depth sampler grid must be at least 1 x 1, got " +
                          std::to_string(grid_cols) + " x " + std::to_string(grid_rows));
  if (!(min_depth >= 0.0) || !(max_depth > min_depth) || !std::isfinite(max_depth))
    throw InvalidArgument("depth range must satisfy 0 <= min_depth < max_depth (finite)");
  if (!(min_valid_fraction >= 0.0 && min_valid_fraction <= 1.0))
    throw InvalidArgument("min_valid_fraction must be in [0, 1]");
  if (pixel_stride < 1) throw InvalidArgument("pixel_stride must be >= 1");
  if (depth_map_cell < 1) throw InvalidArgument("depth_map_cell must be >= 1");
}

cv::Mat depthToMetres(const cv::Mat& depth, double metres_per_unit) {
  if (depth.empty()) throw InvalidInput("depth image is empty");
  cv::Mat out(depth.rows, depth.cols, CV_32FC1);
  if (depth.type() == CV_16UC1) {
    if (!(metres_per_unit > 0.0) || !std::isfinite(metres_per_unit))
      throw InvalidArgument("depth scale must be positive and finite");
    for (int r = 0; r < depth.rows; ++r) {
      const auto* in = depth.ptr<uint16_t>(r);
      auto* o = out.ptr<float>(r);
      for (int c = 0; c < depth.cols; ++c)
        o[c] = in[c] == 0 ? 0.0f : static_cast<float>(in[c] * metres_per_unit);
    }
    return out;
  }
  if (depth.type() == CV_32FC1) {
    for (int r = 0; r < depth.rows; ++r) {
      const auto* in = depth.ptr<float>(r);
      auto* o = out.ptr<float>(r);
      for (int c = 0; c < depth.cols; ++c) o[c] = std::isfinite(in[c]) && in[c] > 0.0f ? in[c] : 0.0f;
    }
    return out;
  }
  throw InvalidInput("depth image must be 16UC1 (millimetres, or TUM PNG units) or 32FC1 (metres); got " +
                     std::to_string(depth.channels()) + " channel(s) of OpenCV depth " +
                     std::to_string(depth.depth()));
}

namespace {

void requireMetres(const cv::Mat& depth_m) {
  if (depth_m.empty() || depth_m.type() != CV_32FC1)
    throw InvalidInput("depth must be a non-empty CV_32FC1 image in metres");
}

struct DepthSample {
  float depth;
  int u;
  int v;
};

bool shallower(const DepthSample& a, const DepthSample& b) {
  if (a.depth != b.depth) return a.depth < b.depth;
  return a.v != b.v ? a.v < b.v : a.u < b.u;  // a strict total order: deterministic medians
}

}  // namespace

Eigen::Matrix3Xd sampleDepthPoints(const cv::Mat& depth_m, const PinholeIntrinsics& intrinsics,
                                   const CameraPose& pose, const DepthSamplerConfig& config) {
  requireMetres(depth_m);
  if (!intrinsics.isValid()) throw InvalidInput("invalid intrinsics for depth sampling");
  // Intrinsics of the depth image itself, when it is a scaled version of the colour image.
  const double sx = static_cast<double>(depth_m.cols) / intrinsics.width;
  const double sy = static_cast<double>(depth_m.rows) / intrinsics.height;
  const double fx = intrinsics.fx * sx, fy = intrinsics.fy * sy;
  const double cx = intrinsics.cx * sx, cy = intrinsics.cy * sy;
  const Eigen::Matrix3d rotation = pose.rotation();

  std::vector<Eigen::Vector3d> points;
  points.reserve(static_cast<size_t>(config.grid_cols) * static_cast<size_t>(config.grid_rows));
  std::vector<DepthSample> cell;
  for (int gr = 0; gr < config.grid_rows; ++gr) {
    const int v0 = gr * depth_m.rows / config.grid_rows;
    const int v1 = (gr + 1) * depth_m.rows / config.grid_rows;
    for (int gc = 0; gc < config.grid_cols; ++gc) {
      const int u0 = gc * depth_m.cols / config.grid_cols;
      const int u1 = (gc + 1) * depth_m.cols / config.grid_cols;
      cell.clear();
      int looked = 0;
      for (int v = v0; v < v1; v += config.pixel_stride) {
        const float* row = depth_m.ptr<float>(v);
        for (int u = u0; u < u1; u += config.pixel_stride) {
          ++looked;
          const float d = row[u];
          if (d >= config.min_depth && d <= config.max_depth) cell.push_back({d, u, v});
        }
      }
      if (cell.empty() || static_cast<double>(cell.size()) < config.min_valid_fraction * looked)
        continue;
      const auto mid = cell.begin() + static_cast<std::ptrdiff_t>(cell.size() / 2);
      std::nth_element(cell.begin(), mid, cell.end(), shallower);
      const double d = mid->depth;
      const Eigen::Vector3d p_cam((mid->u - cx) / fx * d, (mid->v - cy) / fy * d, d);
      points.push_back(rotation * p_cam + pose.position);
    }
  }
  Eigen::Matrix3Xd out(3, static_cast<Eigen::Index>(points.size()));
  for (size_t q = 0; q < points.size(); ++q) out.col(static_cast<Eigen::Index>(q)) = points[q];
  return out;
}

DepthMap downsampleDepth(const cv::Mat& depth_m, const PinholeIntrinsics& intrinsics, int cell) {
  requireMetres(depth_m);
  if (cell < 1) throw InvalidArgument("depth map cell must be >= 1");
  if (!intrinsics.isValid()) throw InvalidInput("invalid intrinsics for the depth map");
  DepthMap map;
  map.cell_width = cell;
  map.cell_height = cell;
  map.cols = (intrinsics.width + cell - 1) / cell;
  map.rows = (intrinsics.height + cell - 1) / cell;
  std::vector<std::vector<float>> buckets(static_cast<size_t>(map.cols) * map.rows);
  // A depth pixel (x, y) covers image pixel (x / sx, y / sy) when the sizes differ.
  const double sx = static_cast<double>(intrinsics.width) / depth_m.cols;
  const double sy = static_cast<double>(intrinsics.height) / depth_m.rows;
  for (int y = 0; y < depth_m.rows; ++y) {
    const float* row = depth_m.ptr<float>(y);
    const int r = std::min(map.rows - 1, static_cast<int>((y + 0.5) * sy) / cell);
    for (int x = 0; x < depth_m.cols; ++x) {
      if (!(row[x] > 0.0f)) continue;
      const int c = std::min(map.cols - 1, static_cast<int>((x + 0.5) * sx) / cell);
      buckets[static_cast<size_t>(r) * map.cols + c].push_back(row[x]);
    }
  }
  map.depth.assign(buckets.size(), 0.0f);
  for (size_t q = 0; q < buckets.size(); ++q) {
    auto& b = buckets[q];
    if (b.empty()) continue;
    const auto mid = b.begin() + static_cast<std::ptrdiff_t>(b.size() / 2);
    std::nth_element(b.begin(), mid, b.end());
    map.depth[q] = *mid;
  }
  return map;
}

}  // namespace view_selection
