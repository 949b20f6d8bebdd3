#include "view_selection/core/occlusion_map.h"

#include "view_selection/core/exceptions.h"

#include <vector>

namespace view_selection::core {

void OcclusionConfig::visitParameters(ParameterVisitor& v) {
  v.section("Occlusion test");
  visitFlag(v, "occlusion_test", enabled,
            "test visibility against each keyframe's downsampled depth map (keyframes with depth)");
  visitReal(v, "occlusion_abs_tolerance", abs_tolerance, 0.0, 1e9,
            "occlusion test: visible when |z - D(p)| <= max(abs, rel * z) [m, scene units]");
  visitReal(v, "occlusion_rel_tolerance", rel_tolerance, 0.0, 1e9,
            "occlusion test: relative part of the tolerance [fraction of z]");
  visitInteger(v, "depth_map_cell", depth_map_cell, 1, 4096,
               "occlusion depth map: one median depth per n x n image pixels");
}

DepthMap makeOcclusionMap(const DepthImage& depth_m, const PinholeIntrinsics& intrinsics,
                          int cell) {
  if (depth_m.empty()) throw InvalidInput("depth must be a non-empty image in metres");
  if (cell < 1) throw InvalidArgument("depth map cell must be >= 1");
  if (!intrinsics.isValid()) throw InvalidInput("invalid intrinsics for the depth map");
  DepthMap map;
  map.cell_width = cell;
  map.cell_height = cell;
  map.cols = (intrinsics.width + cell - 1) / cell;
  map.rows = (intrinsics.height + cell - 1) / cell;
  std::vector<std::vector<float>> buckets(static_cast<size_t>(map.cols) * map.rows);
  // A depth pixel (x, y) covers image pixel (x / sx, y / sy) when the sizes differ.
  const double sx = static_cast<double>(intrinsics.width) / depth_m.width;
  const double sy = static_cast<double>(intrinsics.height) / depth_m.height;
  for (int y = 0; y < depth_m.height; ++y) {
    const float* row = depth_m.row(y);
    const int r = std::min(map.rows - 1, static_cast<int>((y + 0.5) * sy) / cell);
    for (int x = 0; x < depth_m.width; ++x) {
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

}  // namespace view_selection::core
