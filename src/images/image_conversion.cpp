#include "view_selection/images/image_conversion.h"

#include "view_selection/core/exceptions.h"

#include <cmath>
#include <memory>
#include <string>

namespace view_selection::images {

namespace {

template <typename T>
core::ImageView<T> viewOf(const cv::Mat& mat) {
  core::ImageView<T> view;
  if (mat.empty()) return view;
  view.data = mat.data;
  view.width = mat.cols;
  view.height = mat.rows;
  view.channels = mat.channels();
  view.step = mat.step[0];
  view.owner = std::make_shared<const cv::Mat>(mat);  // shares the pixels (reference count)
  return view;
}

template <typename T>
cv::Mat matOfView(const core::ImageView<T>& view, int type) {
  if (view.empty()) return cv::Mat();
  // The pixels are read-only for the core; OpenCV's header type has no const form.
  return cv::Mat(view.height, view.width, type, const_cast<std::uint8_t*>(view.data), view.step);
}

}  // namespace

core::DepthImage depthImageOf(const cv::Mat& depth_m) {
  if (!depth_m.empty() && depth_m.type() != CV_32FC1)
    throw core::InvalidInput("depth must be CV_32FC1 metres (see depthToMetres)");
  return viewOf<float>(depth_m);
}

core::ColourImage colourImageOf(const cv::Mat& image) {
  if (!image.empty() && (image.depth() != CV_8U ||
                         (image.channels() != 1 && image.channels() != 3 && image.channels() != 4)))
    throw core::InvalidInput("image must be 8-bit grey, BGR or BGRA, got OpenCV type " +
                             std::to_string(image.type()));
  return viewOf<std::uint8_t>(image);
}

cv::Mat matOf(const core::DepthImage& depth) { return matOfView(depth, CV_32FC1); }

cv::Mat matOf(const core::ColourImage& image) { return matOfView(image, CV_8UC(image.channels)); }

cv::Mat depthToMetres(const cv::Mat& depth, double metres_per_unit) {
  if (depth.empty()) throw core::InvalidInput("depth image is empty");
  cv::Mat out(depth.rows, depth.cols, CV_32FC1);
  if (depth.type() == CV_16UC1) {
    if (!(metres_per_unit > 0.0) || !std::isfinite(metres_per_unit))
      throw core::InvalidArgument("depth scale must be positive and finite");
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
      for (int c = 0; c < depth.cols; ++c)
        o[c] = std::isfinite(in[c]) && in[c] > 0.0f ? in[c] : 0.0f;
    }
    return out;
  }
  throw core::InvalidInput(
      "depth image must be 16UC1 (millimetres, or TUM PNG units) or 32FC1 (metres); got " +
      std::to_string(depth.channels()) + " channel(s) of OpenCV depth " +
      std::to_string(depth.depth()));
}

}  // namespace view_selection::images
