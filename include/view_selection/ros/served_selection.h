// What services and publishers read: the selection the worker shared last, immutable once
// shared. Readers take it under the served lock (a pointer copy) and never wait for an
// insertion; the worker installs the next one under the same lock, and the one it replaces is
// released outside it.
#pragma once

#include "view_selection/core/selection_output.h"
#include "view_selection/ros/image_cache.h"

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>

namespace view_selection::ros_node {

/// The selection and, with ~save_keyframe_images, the keyframe images. Immutable once shared.
struct ServedSelection {
  uint64_t version = 0;  ///< bumps with every change
  core::SelectionOutput selection;
  /// By keyframe id, ids below image_count (null without ~save_keyframe_images); RAM-bounded.
  std::shared_ptr<const KeyframeImageCache> images;
  size_t image_count = 0;
};

class SharedSelection {
 public:
  /// `generation` is the worker's session generation: a selection of an earlier one is never
  /// installed. It is bumped under this lock (serveEmpty).
  explicit SharedSelection(const std::atomic<uint64_t>& generation) : generation_(generation) {}

  /// The selection shared last; null before the first install.
  std::shared_ptr<const ServedSelection> get() const;
  /// Installs `next` (giving it the next version) unless `generation` is over: after a reset
  /// its empty selection stays. The one replaced is released outside the lock.
  void install(std::shared_ptr<ServedSelection> next, uint64_t generation);
  /// A new generation: under the served lock `under_lock` runs (it bumps the generation), then
  /// an empty selection with the parameters in force is served. Returns the one replaced, for
  /// the caller to release outside its own locks.
  std::shared_ptr<const ServedSelection> serveEmpty(const std::function<void()>& under_lock);

 private:
  const std::atomic<uint64_t>& generation_;
  mutable std::mutex mutex_;  // the served lock
  std::shared_ptr<const ServedSelection> served_;
  uint64_t version_ = 0;  // of served_
};

}  // namespace view_selection::ros_node
