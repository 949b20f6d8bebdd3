// The occlusion test of METHOD.md: a keyframe that has depth keeps a downsampled depth map, and
// a point projecting into it is visible there only when its depth agrees with the map's.
#pragma once

#include "view_selection/core/image.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <algorithm>
#include <cmath>

namespace view_selection::core {

struct OcclusionConfig {
  bool enabled = true;  ///< keep a depth map per keyframe that has depth, and test against it
  double abs_tolerance = 0.05;  ///< visible when |z_j - D_j(p)| <= max(abs, rel * z_j) [m]
  double rel_tolerance = 0.03;  ///< [fraction of z_j]
  int depth_map_cell = 8;       ///< one depth map value per n x n image pixels

  void visitParameters(ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const { checkRanges(*this); }
};

/// The occlusion depth map: median of the valid depths of each cell of `cell` x `cell` pixels,
/// 0 where a cell has none. Cell sizes are in pixels of an image of `intrinsics`' size (the depth
/// image may be a scaled copy of it). Throws InvalidInput for an empty depth image or invalid
/// intrinsics, InvalidArgument for cell < 1.
DepthMap makeOcclusionMap(const DepthImage& depth_m, const PinholeIntrinsics& intrinsics, int cell);

/// True when `map` saw another surface where a point at depth `z` projects (pixel u, v). Cells
/// without depth cannot tell and pass.
inline bool occluded(const DepthMap& map, double u, double v, double z, const OcclusionConfig& c) {
  const double d = map.at(u, v);
  return d > 0.0 && std::abs(z - d) > std::max(c.abs_tolerance, c.rel_tolerance * z);
}

}  // namespace view_selection::core
