// Sample points from a depth image: a grid of cells, one robust point per cell, back-projected to
// world coordinates.
#pragma once

#include "view_selection/core/image.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <Eigen/Core>

namespace view_selection::points {

struct DepthSamplerConfig {
  int grid = 16;           ///< grid x grid cells over the image, one point a cell
  double min_depth = 0.1;  ///< valid depth range [m]; outside is treated as missing
  double max_depth = 10.0;
  double min_valid_fraction = 0.2;  ///< a cell needs this share of valid pixels to give a point
  int pixel_stride = 2;             ///< look at every n-th pixel of a cell in each direction

  void visitParameters(core::ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const;
};

/// One point per grid cell: the valid pixel of median depth, back-projected with `intrinsics`
/// (scaled when the depth image is smaller or larger than the intrinsics' size) and `pose`.
/// Cells without enough valid pixels give no point. Throws InvalidInput for an empty depth image
/// or invalid intrinsics.
Eigen::Matrix3Xd sampleDepthPoints(const core::DepthImage& depth_m,
                                   const core::PinholeIntrinsics& intrinsics,
                                   const core::CameraPose& pose, const DepthSamplerConfig& config);

}  // namespace view_selection::points
