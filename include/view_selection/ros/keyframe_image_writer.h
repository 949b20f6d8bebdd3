// Keyframe images written into a folder as keyframes are accepted (~keyframe_image_dir,
// ~write_keyframe_images): one PNG a keyframe, named as in selection.json, each written once (a
// file already there is kept), on a thread of its own so that the worker never waits for the
// disk. A failure (an unwritable folder, a full disk) or a queue too long loses that image with a
// throttled error, a count and its name (lostNames()), never the node.
//
// No accepted keyframe lacks its image because of a folder switch: the writer holds each
// accepted keyframe's image until the worker has shared a selection with it (shared()), and
// setDirectory() queues the ones held then, in the same step as it switches. Every keyframe below
// Switch::shared is in the selection served from then on; the caller writes those from it.
#pragma once

#include "view_selection/ros/image_cache.h"

#include <sensor_msgs/Image.h>

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace view_selection::ros_node {

class KeyframeImageWriter {
 public:
  struct Stats {
    std::size_t written = 0;  ///< files written
    std::size_t kept = 0;     ///< files that were there already
    std::size_t failed = 0;   ///< images that could not be written
    std::size_t dropped = 0;  ///< images dropped because max_queue images waited already
    std::size_t queued = 0;   ///< waiting now
    std::string last_error;
  };

  /// At most `max_queue` images held in RAM wait (queueFromCache() jobs hold none and do not
  /// count).
  explicit KeyframeImageWriter(std::size_t max_queue = 256);
  ~KeyframeImageWriter();  ///< writes what waits, then joins
  KeyframeImageWriter(const KeyframeImageWriter&) = delete;
  KeyframeImageWriter& operator=(const KeyframeImageWriter&) = delete;

  /// What setDirectory() did.
  struct Switch {
    std::string error;       ///< why the folder cannot be used ("" = fine)
    std::size_t shared = 0;  ///< keyframes below this id are in the served selection: the
                             ///< caller writes those; the writer took the later ones
    std::size_t queued = 0;  ///< accepted keyframes not shared yet, queued here
    std::size_t dropped = 0;  ///< of those, dropped (the queue was full)
  };
  /// The folder from now on ("" = off). Creates it; the keyframes accepted and not yet shared
  /// are queued for it in the same step.
  Switch setDirectory(const std::string& directory);
  std::string directory() const;

  // From the worker, under its state lock:

  /// Keyframe `id` (of the current session) named `name` (relative to the folder) was accepted:
  /// queued when a folder is set, and held until a shared selection has it.
  void accepted(std::size_t id, const std::string& name, sensor_msgs::ImageConstPtr image);
  /// A selection with `keyframes` keyframes is served now.
  void shared(std::size_t keyframes);
  /// A new session (its ids start at 0 again).
  void newSession();

  /// Queues keyframe `id`'s image from `cache` (read when written: no RAM is held while it
  /// waits, so it is never dropped) as `name`; false when no folder is set.
  bool queueFromCache(const std::string& name, std::shared_ptr<const KeyframeImageCache> cache,
                      std::size_t id);
  /// Waits until nothing is queued (at most `timeout` s); true when it is so.
  bool waitIdle(double timeout) const;
  Stats stats() const;
  /// The images dropped or failed since the folder was last set, by name.
  std::vector<std::string> lostNames() const;

 private:
  struct Job {
    std::string path, name;
    sensor_msgs::ImageConstPtr image;                 ///< or, when null:
    std::shared_ptr<const KeyframeImageCache> cache;  ///< read from here
    std::size_t id = 0;
  };
  struct Held {
    std::size_t id;
    std::string name;
    sensor_msgs::ImageConstPtr image;
  };
  void loop();
  void write(const Job& job);
  /// Under mutex_: queues an image held in RAM, or drops it (counted, named) when full.
  bool queueLocked(const std::string& name, sensor_msgs::ImageConstPtr image);
  void lostLocked(const std::string& name, const std::string& error);

  const std::size_t max_queue_;
  mutable std::mutex mutex_;
  mutable std::condition_variable wake_, idle_;
  std::string directory_;
  std::deque<Job> queue_;
  std::size_t holding_ = 0;   // jobs in queue_ that hold an image in RAM
  std::deque<Held> unshared_;  // accepted, not in a served selection yet, ascending id
  std::size_t shared_ = 0;     // keyframes in the served selection
  std::vector<std::string> lost_;
  bool busy_ = false;
  bool stopping_ = false;
  Stats stats_;
  std::thread thread_;  // last
};

}  // namespace view_selection::ros_node
