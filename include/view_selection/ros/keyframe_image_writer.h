// Keyframe images written into a folder as keyframes are accepted (~keyframe_image_dir,
// ~write_keyframe_images): one PNG a keyframe, named as in selection.json, each written once (a
// file already there is kept), on a thread of its own so that the worker never waits for the
// disk. A failure (an unwritable folder, a full disk) loses that image with a throttled error and
// a count, never the node.
#pragma once

#include <sensor_msgs/Image.h>

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <string>
#include <thread>

namespace view_selection::ros_node {

class KeyframeImageWriter {
 public:
  struct Stats {
    std::size_t written = 0;  ///< files written
    std::size_t kept = 0;     ///< files that were there already
    std::size_t failed = 0;   ///< images that could not be written
    std::size_t dropped = 0;  ///< images dropped because max_queue waited already
    std::size_t queued = 0;   ///< waiting now
    std::string last_error;
  };

  explicit KeyframeImageWriter(std::size_t max_queue = 256);
  ~KeyframeImageWriter();  ///< writes what waits, then joins
  KeyframeImageWriter(const KeyframeImageWriter&) = delete;
  KeyframeImageWriter& operator=(const KeyframeImageWriter&) = delete;

  /// The folder from now on ("" = off). Creates it; returns why it cannot be used ("" = fine).
  std::string setDirectory(const std::string& directory);
  std::string directory() const;
  /// Queues the image of a keyframe named `name` (relative to the folder) when a folder is set.
  /// Returns false when no folder is set.
  bool push(const std::string& name, sensor_msgs::ImageConstPtr image);
  /// Waits until nothing is queued (at most `timeout` s); true when it is so.
  bool waitIdle(double timeout) const;
  Stats stats() const;

 private:
  struct Job {
    std::string path;
    sensor_msgs::ImageConstPtr image;
  };
  void loop();
  void write(const Job& job);

  const std::size_t max_queue_;
  mutable std::mutex mutex_;
  mutable std::condition_variable wake_, idle_;
  std::string directory_;
  std::deque<Job> queue_;
  bool busy_ = false;
  bool stopping_ = false;
  Stats stats_;
  std::thread thread_;  // last
};

}  // namespace view_selection::ros_node
