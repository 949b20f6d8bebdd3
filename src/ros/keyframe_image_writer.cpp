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

std::string KeyframeImageWriter::setDirectory(const std::string& directory) {
  std::string error;
  if (!directory.empty()) {
    std::error_code ec;
    fs::create_directories(directory, ec);
    if (ec || !fs::is_directory(directory, ec))
      error = "cannot make folder '" + directory + "': " + (ec ? ec.message() : "not a folder");
  }
  std::lock_guard<std::mutex> lock(mutex_);
  directory_ = error.empty() ? directory : std::string();
  if (!error.empty()) stats_.last_error = error;
  return error;
}

std::string KeyframeImageWriter::directory() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return directory_;
}

bool KeyframeImageWriter::push(const std::string& name, sensor_msgs::ImageConstPtr image) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (directory_.empty() || !image) return false;
    if (queue_.size() >= max_queue_) {
      ++stats_.dropped;
      stats_.last_error = "the image writer is " + std::to_string(max_queue_) +
                          " images behind (the disk is too slow); dropped " + name;
      ROS_ERROR_STREAM_THROTTLE(5.0, "view_selection: " << stats_.last_error);
      return true;
    }
    queue_.push_back({(fs::path(directory_) / name).string(), std::move(image)});
  }
  wake_.notify_one();
  return true;
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
    busy_ = true;
    lock.unlock();
    write(job);
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
    const cv::Mat bgr = imageForCore(job.image);
    io::writeAtomically(job.path, [&](const std::string& tmp) { io::writePng(tmp, bgr); });
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.written;
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.failed;
    stats_.last_error = std::string("keyframe image ") + job.path + ": " + e.what();
    ROS_ERROR_STREAM_THROTTLE(5.0, "view_selection: " << stats_.last_error
                                                      << " (the image is lost; "
                                                      << stats_.failed << " so far)");
  }
}

}  // namespace view_selection::ros_node
