#include "view_selection/ros/keyframe_images.h"

#include <ros/console.h>

namespace view_selection::ros_node {

KeyframeImages::KeyframeImages(const NodeConfig& config, KeyframeImageWriter* writer)
    : config_(config), writer_(writer) {
  if (!config_.save_keyframe_images) return;
  folder_ = std::make_shared<ImageFolder>(config_.image_dir);
  if (!folder_->error().empty())
    ROS_ERROR_STREAM("view_selection: ~image_dir: " << folder_->error()
                                                    << "; keyframe images beyond ~image_cache_mb "
                                                       "will be lost (not exported)");
  cache_ = newCache();
}

std::shared_ptr<KeyframeImageCache> KeyframeImages::newCache() const {
  return std::make_shared<KeyframeImageCache>(
      static_cast<size_t>(config_.image_cache_mb * 1024.0 * 1024.0), folder_);
}

void KeyframeImages::keyframeAccepted(size_t id, const std::string& name,
                                      const sensor_msgs::ImageConstPtr& image,
                                      const CameraModel& camera) {
  if (!cache_ && !writer_) return;
  // A distorted camera's keyframe images are kept rectified, as the exported intrinsics are.
  const sensor_msgs::ImageConstPtr kept =
      camera.rectify ? rectifiedImageMessage(camera, image) : image;
  if (cache_) cache_->push(kept);
  if (writer_) writer_->accepted(id, name, kept);
}

void KeyframeImages::shared(size_t keyframes) {
  if (writer_) writer_->shared(keyframes);
}

void KeyframeImages::continued(size_t keyframes) {
  if (cache_)
    for (size_t i = 0; i < keyframes; ++i) cache_->push(nullptr);
}

void KeyframeImages::newSession() {
  if (cache_) cache_ = newCache();
  if (writer_) writer_->newSession();
}

}  // namespace view_selection::ros_node
