// Keyframe images for ~export (~save_keyframe_images), bounded in RAM: at most ~image_cache_mb
// of them stay in memory; older ones are written to ~image_dir (the message serialised as it
// came, so it reads back bit for bit) by a thread of the cache's own, never by the worker that
// pushes them, and read back when ~export asks for them. A failure to write
// (an unwritable folder, a full disk) loses that image, never the node: it is logged (throttled),
// counted, and ~export says how many images are missing.
#pragma once

#include <sensor_msgs/Image.h>

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace view_selection::ros_node {

/// The folder images are spilled into: `dir`, created when missing, or "" = a new temporary
/// folder (view_selection_images_XXXXXX in the system's temp folder). A folder made here is
/// removed, with everything in it, when the last cache using it is gone. When it cannot be made
/// (or is not a folder), error() says why and every spill fails with that reason. A temporary
/// folder is locked as its owner's (flock on .owner) while it lives; making one removes those
/// of nodes that were killed (removeAbandonedImageFolders).
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
  int lock_fd_ = -1;  ///< holds the lock on .owner (a temporary folder made here)
};

/// Removes the view_selection_images_* folders in `parent` whose owner is gone (their .owner not
/// locked: a node killed before it could remove its folder); returns how many. Folders without
/// .owner are left alone.
size_t removeAbandonedImageFolders(const std::string& parent);

class KeyframeImageCache {
 public:
  struct Stats {
    size_t images = 0;        ///< keyframes pushed (with or without an image)
    size_t in_memory = 0;     ///< images held in RAM (those waiting to be spilled too)
    size_t on_disk = 0;       ///< images spilled to the folder
    size_t spilling = 0;      ///< images waiting to be spilled (still in RAM, readable)
    size_t lost = 0;          ///< images that could not be spilled (dropped)
    size_t memory_bytes = 0;  ///< pixel bytes held in RAM
    std::string last_error;   ///< why the last spill failed; "" when none did
  };

  /// Keeps at most `memory_bytes` of pixel data in RAM, but for images on their way to disk;
  /// the images go into a subfolder of `folder` of this cache's own (made at the first spill,
  /// removed with the cache). Spills are written on a thread of the cache's own, so push()
  /// never waits for the disk.
  KeyframeImageCache(size_t memory_bytes, std::shared_ptr<ImageFolder> folder);
  ~KeyframeImageCache();  ///< stops the spill thread (spills not written yet are abandoned)
  KeyframeImageCache(const KeyframeImageCache&) = delete;
  KeyframeImageCache& operator=(const KeyframeImageCache&) = delete;

  /// Appends the image of keyframe size() (null: the keyframe has none, e.g. it was continued
  /// from ~state_file). While over the budget, the oldest images in RAM are handed to the spill
  /// thread; once as many bytes wait for it as the budget (at least kMinSpillBacklog), the disk
  /// is too slow and the oldest of them are lost (counted, reported) instead of growing RAM.
  void push(sensor_msgs::ImageConstPtr image);
  size_t size() const;
  /// Whether keyframe `id` has an image (in RAM, on its way to disk, or on disk).
  bool has(size_t id) const;
  /// The image of keyframe `id`: from RAM or read back from its file; null when the keyframe has
  /// none or it was lost. Throws core::IoError when a spilled file cannot be read back.
  sensor_msgs::ImageConstPtr get(size_t id) const;
  Stats stats() const;
  /// Waits until no spill is pending (at most `timeout` s); true when so.
  bool waitSpilled(double timeout) const;
  /// This cache's subfolder ("" before the first spill or when it could not be made).
  std::string folder() const;

  static constexpr size_t kMinSpillBacklog = 64u << 20;  ///< [bytes]

 private:
  enum class Where : uint8_t { kNone, kMemory, kSpilling, kDisk, kLost };
  struct Entry {
    Where where = Where::kNone;
    sensor_msgs::ImageConstPtr image;  ///< in RAM (kMemory, kSpilling)
  };
  void spillLoop();
  /// Writes `image` as keyframe `id`'s file (without mutex_); "" or why it failed.
  std::string spill(size_t id, const sensor_msgs::Image& image);
  /// Under mutex_: `id` is no longer in RAM (spilled, or lost with `error`).
  void releaseLocked(size_t id, bool spilled, const std::string& error);
  std::string fileOf(const std::string& dir, size_t id) const;
  void reportLocked(const std::string& error);

  const size_t budget_;
  std::shared_ptr<ImageFolder> base_;
  mutable std::mutex mutex_;
  mutable std::condition_variable wake_, spilled_;
  std::vector<Entry> entries_;
  std::deque<size_t> memory_order_;  ///< ids in RAM and not spilling, oldest first
  std::deque<size_t> spill_queue_;   ///< ids waiting for the spill thread, oldest first
  size_t memory_bytes_ = 0;          ///< every image in RAM
  size_t spill_bytes_ = 0;           ///< of them, those waiting to be spilled
  size_t on_disk_ = 0, lost_ = 0;
  bool spill_busy_ = false, stopping_ = false;
  std::string dir_;         ///< this cache's subfolder, once made
  std::string last_error_;
  std::chrono::steady_clock::time_point last_report_{};
  size_t unreported_ = 0;  ///< failures since the last logged one
  std::thread spill_thread_;  // last
};

}  // namespace view_selection::ros_node
