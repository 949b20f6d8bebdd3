#include "view_selection/ros/served_selection.h"

namespace view_selection::ros_node {

std::shared_ptr<const ServedSelection> SharedSelection::get() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return served_;
}

void SharedSelection::install(std::shared_ptr<ServedSelection> next, uint64_t generation) {
  std::shared_ptr<const ServedSelection> old;  // released after the lock
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (generation != generation_.load()) return;  // a reset since: its empty selection stays
    next->version = ++version_;
    old = std::move(served_);
    served_ = std::move(next);
  }
}

std::shared_ptr<const ServedSelection> SharedSelection::serveEmpty(
    const std::function<void()>& under_lock) {
  std::lock_guard<std::mutex> lock(mutex_);
  under_lock();
  // Empty at once, with the parameters in force; the worker's thread clears the selector
  // itself before its next frame and shares its own empty selection then.
  auto empty = std::make_shared<ServedSelection>();
  empty->version = ++version_;
  empty->selection.config = served_->selection.config;
  empty->selection.params = served_->selection.params;
  std::shared_ptr<const ServedSelection> old = std::move(served_);
  served_ = std::move(empty);
  return old;
}

}  // namespace view_selection::ros_node
