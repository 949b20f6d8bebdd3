// The worker's image output: each accepted keyframe's image goes to the RAM-bounded cache that
// served selections share for ~export (~save_keyframe_images, ros/image_cache) and to the
// keyframe image writer's thread (~keyframe_image_dir, ros/keyframe_image_writer). Called under
// the worker's state lock; the cache and the writer take only their own locks.
#pragma once

#include "view_selection/ros/camera_model.h"
#include "view_selection/ros/image_cache.h"
#include "view_selection/ros/keyframe_image_writer.h"
#include "view_selection/ros/node_config.h"

#include <sensor_msgs/Image.h>

#include <memory>
#include <string>

namespace view_selection::ros_node {

class KeyframeImages {
 public:
  /// `writer`: where accepted keyframes' images are written, or null.
  KeyframeImages(const NodeConfig& config, KeyframeImageWriter* writer);

  /// Keyframe `id` named `name` was accepted: its image kept (rectified for a distorted camera,
  /// as the exported intrinsics are) in the cache and handed to the writer.
  void keyframeAccepted(size_t id, const std::string& name,
                        const sensor_msgs::ImageConstPtr& image, const CameraModel& camera);
  /// A selection with `keyframes` keyframes is served: the writer need not hold their images
  /// for a folder switch any more.
  void shared(size_t keyframes);
  /// `keyframes` continued from ~state_file, which keeps no images: they have none (null).
  void continued(size_t keyframes);
  /// A new session: a new cache (selections shared before keep the old one).
  void newSession();
  /// What a served selection shares: the cache (null without ~save_keyframe_images) and the
  /// keyframes it holds.
  std::shared_ptr<const KeyframeImageCache> cache() const { return cache_; }
  size_t count() const { return cache_ ? cache_->size() : 0; }

 private:
  std::shared_ptr<KeyframeImageCache> newCache() const;

  const NodeConfig& config_;
  KeyframeImageWriter* writer_;
  std::shared_ptr<ImageFolder> folder_;         // with ~save_keyframe_images: ~image_dir
  std::shared_ptr<KeyframeImageCache> cache_;  // by keyframe id; a new one each session
};

}  // namespace view_selection::ros_node
