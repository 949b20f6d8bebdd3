#include "view_selection/ros/keyframe_image_writer.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/atomic_file.h"
#include "view_selection/io/selection_plot.h"
#include "view_selection/ros/conversions.h"

#include <ros/console.h>

#include <chrono>
#include <filesystem>

namespace fs = std::filesystem;

namespace view_selection::ros_node {

KeyframeImageWriter::KeyframeImageWriter(std::size_t max_queue)
    : max_queue_(max_queue), thread_([this] { loop(); }) {}

KeyframeImageWriter::~KeyframeImageWriter() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

KeyframeImageWriter::Switch KeyframeImageWriter::setDirectory(const std::string& directory) {
  Switch out;
  if (!directory.empty()) {
    std::error_code ec;
    fs::create_directories(directory, ec);
    if (ec || !fs::is_directory(directory, ec))
      out.error = "cannot make folder '" + directory + "': " + (ec ? ec.message() : "not a folder");
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    directory_ = out.error.empty() ? directory : std::string();
    lost_.clear();
    if (!out.error.empty()) stats_.last_error = out.error;
    out.shared = shared_;
    // In the same step as the switch: the keyframes accepted and not in the served selection
    // yet, which the caller cannot see.
    if (!directory_.empty())
      for (const Held& h : unshared_) {
        ++out.queued;
        if (!queueLocked(h.name, h.image)) ++out.dropped;
      }
  }
  wake_.notify_one();
  return out;
}

std::string KeyframeImageWriter::directory() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return directory_;
}

void KeyframeImageWriter::lostLocked(const std::string& name, const std::string& error) {
  stats_.last_error = error;
  // Bounded: a consumer asks again for what it lacks; the names of a long outage are not kept.
  if (lost_.size() < 10000) lost_.push_back(name);
}

bool KeyframeImageWriter::queueLocked(const std::string& name, sensor_msgs::ImageConstPtr image) {
  if (holding_ >= max_queue_) {
    ++stats_.dropped;
    lostLocked(name, "the image writer is " + std::to_string(max_queue_) +
                         " images behind (the disk is too slow); dropped " + name);
    ROS_ERROR_STREAM_THROTTLE(5.0, "view_selection: " << stats_.last_error);
    return false;
  }
  ++holding_;
  queue_.push_back({(fs::path(directory_) / name).string(), name, std::move(image), nullptr, 0});
  return true;
}

void KeyframeImageWriter::accepted(std::size_t id, const std::string& name,
                                   sensor_msgs::ImageConstPtr image) {
  if (!image) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    unshared_.push_back({id, name, image});
    if (directory_.empty()) return;
    queueLocked(name, std::move(image));
  }
  wake_.notify_one();
}

void KeyframeImageWriter::shared(std::size_t keyframes) {
  std::lock_guard<std::mutex> lock(mutex_);
  shared_ = keyframes;
  while (!unshared_.empty() && unshared_.front().id < keyframes) unshared_.pop_front();
}

void KeyframeImageWriter::newSession() {
  std::lock_guard<std::mutex> lock(mutex_);
  unshared_.clear();
  shared_ = 0;
}

bool KeyframeImageWriter::queueFromCache(const std::string& name,
                                         std::shared_ptr<const KeyframeImageCache> cache,
                                         std::size_t id) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (directory_.empty() || !cache) return false;
    queue_.push_back({(fs::path(directory_) / name).string(), name, nullptr, std::move(cache), id});
  }
  wake_.notify_one();
  return true;
}

std::vector<std::string> KeyframeImageWriter::lostNames() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return lost_;
}

bool KeyframeImageWriter::waitIdle(double timeout) const {
  std::unique_lock<std::mutex> lock(mutex_);
  return idle_.wait_for(lock, std::chrono::duration<double>(timeout),
                        [this] { return queue_.empty() && !busy_; });
}

KeyframeImageWriter::Stats KeyframeImageWriter::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  Stats s = stats_;
  s.queued = queue_.size();
  return s;
}

void KeyframeImageWriter::loop() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (true) {
    wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
    if (queue_.empty()) {
      if (stopping_) return;
      continue;
    }
    Job job = std::move(queue_.front());
    queue_.pop_front();
    if (job.image) --holding_;
    busy_ = true;
    lock.unlock();
    write(job);
    job = Job{};  // the image released outside the lock
    lock.lock();
    busy_ = false;
    if (queue_.empty()) idle_.notify_all();
  }
}

void KeyframeImageWriter::write(const Job& job) {
  std::error_code ec;
  if (fs::exists(job.path, ec)) {  // written once: by an earlier run, or an earlier request
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.kept;
    return;
  }
  try {
    fs::create_directories(fs::path(job.path).parent_path(), ec);
    if (ec)
      throw core::IoError("cannot make folder '" + fs::path(job.path).parent_path().string() +
                          "': " + ec.message());
    // A keyframe image from the cache is read now (back from disk when it was spilled).
    const sensor_msgs::ImageConstPtr image = job.image ? job.image : job.cache->get(job.id);
    if (!image) throw core::IoError("the node no longer has the image");
    const cv::Mat bgr = imageForCore(image);
    io::writeAtomically(job.path, [&](const std::string& tmp) { io::writePng(tmp, bgr); });
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.written;
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.failed;
    lostLocked(job.name, std::string("keyframe image ") + job.path + ": " + e.what());
    ROS_ERROR_STREAM_THROTTLE(5.0, "view_selection: " << stats_.last_error
                                                      << " (the image is lost; "
                                                      << stats_.failed << " so far)");
  }
}

}  // namespace view_selection::ros_node
