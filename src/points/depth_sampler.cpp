#include "view_selection/points/depth_sampler.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace view_selection::points {

void DepthSamplerConfig::visitParameters(core::ParameterVisitor& v) {
  v.section("Points from depth");
  core::visitInteger(v, "grid", grid, 1, 256, "depth sampling grid, N x N cells, one point a cell");
  core::visitReal(v, "depth_min", min_depth, 0.0, 1e9, "valid depth range: nearest [m]");
  core::visitReal(v, "depth_max", max_depth, 0.0, 1e9, "valid depth range: farthest [m]");
  core::visitReal(v, "depth_min_valid_fraction", min_valid_fraction, 0.0, 1.0,
                  "a cell needs this share of valid depth pixels to give a point");
  core::visitInteger(v, "depth_pixel_stride", pixel_stride, 1, 1024,
                     "look at every n-th pixel of a cell in each direction");
}

void DepthSamplerConfig::validate() const {
  core::checkRanges(*this);
  if (!(max_depth > min_depth))
    throw core::InvalidArgument("depth range must satisfy depth_min < depth_max");
}

namespace {

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

Eigen::Matrix3Xd sampleDepthPoints(const core::DepthImage& depth_m,
                                   const core::PinholeIntrinsics& intrinsics,
                                   const core::CameraPose& pose, const DepthSamplerConfig& config) {
  if (depth_m.empty()) throw core::InvalidInput("depth must be a non-empty image in metres");
  if (!intrinsics.isValid()) throw core::InvalidInput("invalid intrinsics for depth sampling");
  // Intrinsics of the depth image itself, when it is a scaled version of the colour image.
  const double sx = static_cast<double>(depth_m.width) / intrinsics.width;
  const double sy = static_cast<double>(depth_m.height) / intrinsics.height;
  const double fx = intrinsics.fx * sx, fy = intrinsics.fy * sy;
  const double cx = intrinsics.cx * sx, cy = intrinsics.cy * sy;
  const Eigen::Matrix3d rotation = pose.rotation();

  std::vector<Eigen::Vector3d> points;
  points.reserve(static_cast<size_t>(config.grid) * static_cast<size_t>(config.grid));
  std::vector<DepthSample> cell;
  for (int gr = 0; gr < config.grid; ++gr) {
    const int v0 = gr * depth_m.height / config.grid;
    const int v1 = (gr + 1) * depth_m.height / config.grid;
    for (int gc = 0; gc < config.grid; ++gc) {
      const int u0 = gc * depth_m.width / config.grid;
      const int u1 = (gc + 1) * depth_m.width / config.grid;
      cell.clear();
      int looked = 0;
      for (int v = v0; v < v1; v += config.pixel_stride) {
        const float* row = depth_m.row(v);
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

}  // namespace view_selection::points
