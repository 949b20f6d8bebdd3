// Keyframe images for ~export (~save_keyframe_images), bounded in RAM: at most ~image_cache_mb
// of them stay in memory; older ones are written to ~image_dir (the message serialised as it
// came, so it reads back bit for bit) and read back when ~export asks for them. A failure to write
// (an unwritable folder, a full disk) loses that image, never the node: it is logged (throttled),
// counted, and ~export says how many images are missing.
#pragma once

#include <sensor_msgs/Image.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace view_selection::ros_node {

/// The folder images are spilled into: `dir`, created when missing, or "" = a new temporary
/// folder (view_selection_images_XXXXXX in the system's temp folder). A folder made here is
/// removed, with everything in it, when the last cache using it is gone. When it cannot be made
/// (or is not a folder), error() says why and every spill fails with that reason.
class ImageFolder {
 public:
  explicit ImageFolder(const std::string& dir);
  ~ImageFolder();
  ImageFolder(const ImageFolder&) = delete;
  ImageFolder& operator=(const ImageFolder&) = delete;

  const std::string& path() const { return path_; }
  bool created() const { return created_; }
  /// Why the folder is unusable; "" when it is usable.
  const std::string& error() const { return error_; }

 private:
  std::string path_, error_;
  bool created_ = false;
};

class KeyframeImageCache {
 public:
  struct Stats {
    size_t images = 0;        ///< keyframes pushed (with or without an image)
    size_t in_memory = 0;     ///< images held in RAM
    size_t on_disk = 0;       ///< images spilled to the folder
    size_t lost = 0;          ///< images that could not be spilled (dropped)
    size_t memory_bytes = 0;  ///< pixel bytes held in RAM
    std::string last_error;   ///< why the last spill failed; "" when none did
  };

  /// Keeps at most `memory_bytes` of pixel data in RAM; the images go into a subfolder of
  /// `folder` of this cache's own (made at the first spill, removed with the cache).
  KeyframeImageCache(size_t memory_bytes, std::shared_ptr<ImageFolder> folder);
  ~KeyframeImageCache();
  KeyframeImageCache(const KeyframeImageCache&) = delete;
  KeyframeImageCache& operator=(const KeyframeImageCache&) = delete;

  /// Appends the image of keyframe size() (null: the keyframe has none, e.g. it was continued
  /// from ~state_file). Spills the oldest images in RAM while over the budget.
  void push(sensor_msgs::ImageConstPtr image);
  size_t size() const;
  /// The image of keyframe `id`: from RAM or read back from its file; null when the keyframe has
  /// none or it was lost. Throws core::IoError when a spilled file cannot be read back.
  sensor_msgs::ImageConstPtr get(size_t id) const;
  Stats stats() const;
  /// This cache's subfolder ("" before the first spill or when it could not be made).
  std::string folder() const;

 private:
  enum class Where : uint8_t { kNone, kMemory, kDisk, kLost };
  struct Entry {
    Where where = Where::kNone;
    sensor_msgs::ImageConstPtr image;  ///< in RAM
  };
  /// Under mutex_: writes entry `id` to its file; false (with error_) when it cannot.
  bool spillLocked(size_t id);
  std::string fileLocked(size_t id) const;
  void reportLocked(const std::string& error);

  const size_t budget_;
  std::shared_ptr<ImageFolder> base_;
  mutable std::mutex mutex_;
  std::vector<Entry> entries_;
  std::deque<size_t> memory_order_;  ///< ids in RAM, oldest first
  size_t memory_bytes_ = 0;
  size_t on_disk_ = 0, lost_ = 0;
  std::string dir_;         ///< this cache's subfolder, once made
  std::string last_error_;
  std::chrono::steady_clock::time_point last_report_{};
  size_t unreported_ = 0;  ///< failures since the last logged one
};

}  // namespace view_selection::ros_node
