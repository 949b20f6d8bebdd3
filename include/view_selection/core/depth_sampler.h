// Sample points from a depth image: a grid of cells, one robust point per cell, back-projected to
// world coordinates; and the downsampled depth map a keyframe keeps for the occlusion test.
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace view_selection {

struct DepthSamplerConfig {
  int grid_cols = 16;                 ///< cells across the image
  int grid_rows = 16;                 ///< cells down the image (16 x 16 = up to 256 points)
  double min_depth = 0.1;             ///< valid depth range [m]; outside is treated as missing
  double max_depth = 10.0;
  double min_valid_fraction = 0.2;    ///< a cell needs this share of valid pixels to give a point
  int pixel_stride = 2;               ///< look at every n-th pixel of a cell in each direction
  int depth_map_cell = 8;             ///< occlusion depth map: one value per n x n pixels

  /// Throws InvalidArgument naming the first field out of range.
  void validate() const;
};

/// Depth in metres as CV_32FC1 (0 = invalid). Accepts 16UC1 (scaled by `metres_per_unit`:
/// 0.001 for millimetres, 1/5000 for TUM PNGs) and 32FC1 metres (NaN and non-positive become 0).
/// Throws InvalidInput for any other type or an empty image.
cv::Mat depthToMetres(const cv::Mat& depth, double metres_per_unit);

/// One point per grid cell: the valid pixel of median depth, back-projected with `intrinsics`
/// (scaled when the depth image is smaller or larger than the intrinsics' size) and `pose`.
/// `depth_m` must be CV_32FC1 metres. Cells without enough valid pixels give no point.
Eigen::Matrix3Xd sampleDepthPoints(const cv::Mat& depth_m, const PinholeIntrinsics& intrinsics,
                                   const CameraPose& pose, const DepthSamplerConfig& config);

/// The occlusion depth map: median of the valid depths of each cell of `cell` x `cell` pixels,
/// 0 where a cell has none. Cell sizes are expressed in pixels of an image of `intrinsics`' size.
DepthMap downsampleDepth(const cv::Mat& depth_m, const PinholeIntrinsics& intrinsics, int cell);

}  // namespace view_selection
