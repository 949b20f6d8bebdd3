#include "view_selection/ros/frame_queue.h"

namespace view_selection::ros_node {

FrameQueue::FrameQueue(size_t capacity, InputStatistics& statistics,
                       const std::atomic<uint64_t>& generation)
    : capacity_(capacity), statistics_(statistics), generation_(generation) {}

FrameQueue::Pushed FrameQueue::push(PendingFrame frame) {
  Pushed out;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return out;
    // An image that arrived before a ~reset or a time jump: not part of the new session.
    if (frame.generation != generation_.load()) return out;
    if (queue_.size() >= capacity_) {
      out.overflow = std::move(queue_.front());
      queue_.pop_front();
    }
    // Counted under the lock a new generation starts a new session under: a frame belongs to
    // exactly one session. No other lock: the inputs never wait for an insertion.
    const uint64_t session = statistics_.frameReceived();
    queue_.push_back({std::move(frame), generation_.load(), session, ros::WallTime::now()});
    queued_count_ = queue_.size();
    out.queued = true;
  }
  wake_.notify_one();
  return out;
}

size_t FrameQueue::pending(double* oldest_age) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (oldest_age)
    *oldest_age = queue_.empty() ? 0.0 : (ros::WallTime::now() - queue_.front().queued).toSec();
  return queue_.size();
}

void FrameQueue::startGeneration(const std::function<void()>& under_lock) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.clear();
    queued_count_ = 0;
    under_lock();
  }
  wake_.notify_one();
}

void FrameQueue::reconfigure(const core::ViewSelectorConfig& config) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_config_ = config;
  }
  wake_.notify_one();
}

void FrameQueue::setMap(Eigen::Matrix3Xd points) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_map_ = std::move(points);
  }
  wake_.notify_one();
}

void FrameQueue::requestSave(std::function<void()> save) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_saves_.push_back(std::move(save));
  }
  wake_.notify_one();
}

FrameQueue::Requests FrameQueue::takeRequests() {
  std::lock_guard<std::mutex> lock(mutex_);
  Requests r;
  r.config = std::move(pending_config_);
  pending_config_.reset();
  r.map = std::move(pending_map_);
  pending_map_.reset();
  r.saves.swap(pending_saves_);
  r.generation = generation_.load();
  return r;
}

std::optional<QueuedFrame> FrameQueue::next(uint64_t applied_generation,
                                            const std::function<void()>& idle, bool* stop) {
  std::unique_lock<std::mutex> lock(mutex_);
  if (queue_.empty()) {
    lock.unlock();
    idle();
    lock.lock();
  }
  const auto requested = [&] {
    return pending_config_ || pending_map_ || !pending_saves_.empty() ||
           generation_.load() != applied_generation;
  };
  wake_.wait(lock, [&] { return stopping_ || !queue_.empty() || requested(); });
  // On stop, the frames still queued are handled first (each becomes a keyframe or a counted
  // drop); then the worker stops.
  *stop = stopping_ && queue_.empty() && !requested();
  if (queue_.empty() || requested()) return std::nullopt;  // stop, or a request to apply first
  QueuedFrame frame = std::move(queue_.front());
  queue_.pop_front();
  queued_count_ = queue_.size();
  return frame;
}

bool FrameQueue::stopping() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stopping_;
}

void FrameQueue::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
}

}  // namespace view_selection::ros_node
