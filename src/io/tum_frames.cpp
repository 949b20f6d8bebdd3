#include "view_selection/io/tum_frames.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/images/image_conversion.h"

#include <opencv2/imgcodecs.hpp>

#include <filesystem>

namespace view_selection::io {

namespace {

cv::Mat readImage(const std::string& path, int flags) {
  cv::Mat image;
  try {
    image = cv::imread(path, flags);
  } catch (const cv::Exception& e) {
    throw core::IoError("cannot read image '" + path + "': " + e.what());
  }
  if (image.empty())
    throw core::IoError("cannot read image '" + path + "' (missing, unreadable or not an image)");
  return image;
}

}  // namespace

core::Frame loadTumFrame(const TumDataset& dataset, const TumFrame& tum,
                         const FrameLoadOptions& options) {
  const std::filesystem::path root(dataset.root);
  core::Frame frame;
  frame.stamp = tum.stamp;
  frame.image_name = dataset.imageName(tum);
  frame.intrinsics = dataset.intrinsics;
  frame.pose = tum.pose;
  if (options.depth && dataset.has_depth && !tum.depth_path.empty()) {
    const std::string path = (root / tum.depth_path).string();
    try {
      frame.depth = images::depthImageOf(
          images::depthToMetres(readImage(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE),
                                dataset.depth_metres_per_unit));
    } catch (const core::InvalidInput& e) {
      throw core::InvalidInput("depth image '" + path + "': " + e.what());
    }
  }
  if (options.image)
    frame.image =
        images::colourImageOf(readImage((root / tum.rgb_path).string(), cv::IMREAD_COLOR));
  return frame;
}

}  // namespace view_selection::io
