// Images as the core reads them, without OpenCV: a read-only view of rows of pixels, with an
// owner that keeps the pixels alive (a cv::Mat, a ROS message, a vector). Conversions from and
// to cv::Mat are in images/image_conversion.h; no pixel is copied by either.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

namespace view_selection::core {

/// `height` rows of `width` pixels of `channels` elements of T; row r starts `r * step` bytes
/// after `data`.
template <typename T>
struct ImageView {
  const std::uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  int channels = 1;
  std::size_t step = 0;               ///< bytes from one row to the next
  std::shared_ptr<const void> owner;  ///< keeps `data` alive; may be null for borrowed pixels

  bool empty() const { return data == nullptr || width <= 0 || height <= 0; }
  const T* row(int r) const {
    return reinterpret_cast<const T*>(data + static_cast<std::size_t>(r) * step);
  }
};

/// Depth in metres, one channel; 0 marks a pixel without valid depth.
using DepthImage = ImageView<float>;
/// 8-bit colour (3 channels BGR, or 4 BGRA) or grey (1 channel).
using ColourImage = ImageView<std::uint8_t>;

}  // namespace view_selection::core
