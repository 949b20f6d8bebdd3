// cv::Mat and the core's image views (core/image.h), both ways, without copying pixels; and depth
// in any of the usual encodings to metres.
#pragma once

#include "view_selection/core/image.h"

#include <opencv2/core.hpp>

namespace view_selection::images {

/// A view of `depth_m` (CV_32FC1 metres) that keeps the Mat's pixels alive. Throws InvalidInput
/// for another type. An empty Mat gives an empty view.
core::DepthImage depthImageOf(const cv::Mat& depth_m);
/// A view of an 8-bit grey, BGR or BGRA Mat that keeps its pixels alive. Throws InvalidInput for
/// another type. An empty Mat gives an empty view.
core::ColourImage colourImageOf(const cv::Mat& image);

/// A Mat header over the view's pixels (no copy); valid while the view's owner lives.
cv::Mat matOf(const core::DepthImage& depth);
cv::Mat matOf(const core::ColourImage& image);

/// Depth in metres as CV_32FC1 (0 = invalid). Accepts 16UC1 (scaled by `metres_per_unit`:
/// 0.001 for millimetres, 1/5000 for TUM PNGs) and 32FC1 metres (NaN and non-positive become 0).
/// Throws InvalidInput for any other type or an empty image.
cv::Mat depthToMetres(const cv::Mat& depth, double metres_per_unit);

}  // namespace view_selection::images
