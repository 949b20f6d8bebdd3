#include "view_selection/ros/image_cache.h"

#include "view_selection/core/exceptions.h"

#include <ros/console.h>
#include <ros/serialization.h>

#include <boost/make_shared.hpp>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

namespace view_selection::ros_node {

namespace fs = std::filesystem;

namespace {

constexpr double kReportPeriod = 10.0;  // [s, wall] at most one logged spill failure

/// mkdtemp under `parent`; "" with `error` set when it fails.
std::string makeUniqueFolder(const fs::path& parent, const std::string& prefix,
                             std::string& error) {
  std::string pattern = (parent / (prefix + "XXXXXX")).string();
  std::vector<char> buffer(pattern.begin(), pattern.end());
  buffer.push_back('\0');
  if (!::mkdtemp(buffer.data())) {
    error = "cannot create a folder in '" + parent.string() + "': " + std::strerror(errno);
    return {};
  }
  return std::string(buffer.data());
}

constexpr const char* kTempPrefix = "view_selection_images_";
constexpr const char* kOwnerFile = ".owner";  // flock()ed for as long as the folder's owner lives

/// Locks `folder`/.owner for as long as the returned descriptor stays open (-1 when it cannot:
/// the folder then works, but is never taken for abandoned). The lock is taken on a file of
/// another name, renamed once locked: a sweep never sees an .owner not locked yet.
int lockAsOwner(const fs::path& folder) {
  const std::string tmp = (folder / ".owner.new").string();
  const int fd = ::open(tmp.c_str(), O_CREAT | O_WRONLY | O_CLOEXEC | O_NOFOLLOW, 0600);
  if (fd < 0) return -1;
  const std::string pid = std::to_string(::getpid()) + "\n";  // for a reader; the lock is what counts
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0 || ::write(fd, pid.data(), pid.size()) < 0 ||
      ::rename(tmp.c_str(), (folder / kOwnerFile).c_str()) != 0) {
    ::close(fd);
    ::unlink(tmp.c_str());
    return -1;
  }
  return fd;
}

}  // namespace

size_t removeAbandonedImageFolders(const std::string& parent) {
  size_t removed = 0;
  std::error_code ec;
  for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec)) {
    const fs::path folder = it->path();
    if (folder.filename().string().rfind(kTempPrefix, 0) != 0 || !it->is_directory(ec) || it->is_symlink(ec))
      continue;
    // A folder without .owner (made by an older version, or its lock could not be taken) is
    // left alone: nothing says its owner is gone.
    const int fd = ::open((folder / kOwnerFile).c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {  // nobody holds it: its node was killed
      std::error_code rm;
      if (fs::remove_all(folder, rm) > 0 && !rm) ++removed;
    }
    ::close(fd);
  }
  return removed;
}

ImageFolder::ImageFolder(const std::string& dir) {
  if (dir.empty()) {
    std::error_code ec;
    const fs::path tmp = fs::temp_directory_path(ec);
    if (ec) {
      error_ = "no temporary folder: " + ec.message();
      return;
    }
    // What killed nodes left (a SIGKILL runs no destructor): their spilled images, up to the
    // whole session's, would stay in the temp folder until a reboot.
    if (const size_t n = removeAbandonedImageFolders(tmp.string()))
      ROS_INFO_STREAM("view_selection: removed " << n << " image folder(s) in " << tmp.string()
                                                 << " left by nodes that were killed");
    path_ = makeUniqueFolder(tmp, kTempPrefix, error_);
    created_ = !path_.empty();
    if (created_) lock_fd_ = lockAsOwner(path_);
    return;
  }
  path_ = dir;
  std::error_code ec;
  if (fs::exists(path_, ec)) {
    if (!fs::is_directory(path_, ec))
      error_ = "'" + path_ + "' is not a folder";
    else if (::access(path_.c_str(), W_OK | X_OK) != 0)
      error_ = "cannot write into '" + path_ + "': " + std::strerror(errno);
    return;
  }
  created_ = fs::create_directories(path_, ec);
  if (ec) {
    created_ = false;
    error_ = "cannot create folder '" + path_ + "': " + ec.message();
  }
}

ImageFolder::~ImageFolder() {
  if (!created_) return;
  std::error_code ec;
  fs::remove_all(path_, ec);
  if (lock_fd_ >= 0) ::close(lock_fd_);
  if (ec)
    ROS_WARN_STREAM("view_selection: could not remove the image folder '" << path_
                                                                         << "': " << ec.message());
}

KeyframeImageCache::KeyframeImageCache(size_t memory_bytes, std::shared_ptr<ImageFolder> folder)
    : budget_(memory_bytes), base_(std::move(folder)), spill_thread_([this] { spillLoop(); }) {}

KeyframeImageCache::~KeyframeImageCache() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (spill_thread_.joinable()) spill_thread_.join();
  if (dir_.empty()) return;
  std::error_code ec;
  fs::remove_all(dir_, ec);
  if (ec)
    ROS_WARN_STREAM("view_selection: could not remove the image folder '" << dir_
                                                                         << "': " << ec.message());
}

std::string KeyframeImageCache::fileOf(const std::string& dir, size_t id) const {
  return (fs::path(dir) / (std::to_string(id) + ".image")).string();
}

void KeyframeImageCache::reportLocked(const std::string& error) {
  last_error_ = error;
  const auto now = std::chrono::steady_clock::now();
  if (last_report_ != std::chrono::steady_clock::time_point{} &&
      std::chrono::duration<double>(now - last_report_).count() < kReportPeriod) {
    ++unreported_;
    return;
  }
  ROS_ERROR_STREAM("view_selection: keyframe image lost (~image_cache_mb is full and it cannot "
                   "go to ~image_dir): "
                   << error << "; ~export will lack it"
                   << (unreported_ > 0
                           ? " (" + std::to_string(unreported_) + " more since the last message)"
                           : std::string()));
  unreported_ = 0;
  last_report_ = now;
}

std::string KeyframeImageCache::spill(size_t id, const sensor_msgs::Image& image) {
  std::string dir;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!base_ || !base_->error().empty()) return base_ ? base_->error() : "no image folder";
    if (dir_.empty()) {
      std::string error;
      dir_ = makeUniqueFolder(base_->path(), "session_", error);
      if (dir_.empty()) return error;
    }
    dir = dir_;
  }
  const uint32_t length = ros::serialization::serializationLength(image);
  std::vector<uint8_t> bytes(length);
  ros::serialization::OStream out(bytes.data(), length);
  ros::serialization::serialize(out, image);
  const std::string path = fileOf(dir, id);
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return "cannot write '" + path + "': " + std::strerror(errno);
  const size_t written = std::fwrite(bytes.data(), 1, bytes.size(), f);
  const int write_errno = errno;
  const bool flushed = std::fflush(f) == 0;
  const int flush_errno = errno;
  const bool closed = std::fclose(f) == 0;
  if (written != bytes.size() || !flushed || !closed) {
    const int e = written != bytes.size() ? write_errno : flushed ? errno : flush_errno;
    std::error_code ec;
    fs::remove(path, ec);
    return "cannot write '" + path + "': " + std::strerror(e);
  }
  return {};
}

void KeyframeImageCache::releaseLocked(size_t id, bool spilled, const std::string& error) {
  Entry& e = entries_[id];
  memory_bytes_ -= e.image->data.size();
  e.image.reset();
  e.where = spilled ? Where::kDisk : Where::kLost;
  ++(spilled ? on_disk_ : lost_);
  if (!spilled) reportLocked(error);
}

void KeyframeImageCache::spillLoop() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (true) {
    wake_.wait(lock, [this] { return stopping_ || !spill_queue_.empty(); });
    if (stopping_) return;
    const size_t id = spill_queue_.front();
    spill_queue_.pop_front();
    const sensor_msgs::ImageConstPtr image = entries_[id].image;  // kept in RAM until written
    spill_busy_ = true;
    lock.unlock();
    const std::string error = spill(id, *image);  // the disk, outside the lock
    lock.lock();
    spill_busy_ = false;
    spill_bytes_ -= image->data.size();
    releaseLocked(id, error.empty(), error);
    if (spill_queue_.empty()) spilled_.notify_all();
  }
}

void KeyframeImageCache::push(sensor_msgs::ImageConstPtr image) {
  bool wake = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const size_t id = entries_.size();
    Entry entry;
    if (image) {
      entry.where = Where::kMemory;
      memory_bytes_ += image->data.size();
      entry.image = std::move(image);
      memory_order_.push_back(id);
    }
    entries_.push_back(std::move(entry));
    // Over the budget: the oldest images in RAM go to the spill thread (still readable meanwhile).
    const bool unusable = !base_ || !base_->error().empty();
    while (memory_bytes_ - spill_bytes_ > budget_ && !memory_order_.empty()) {
      const size_t oldest = memory_order_.front();
      memory_order_.pop_front();
      if (unusable) {  // known at once: no disk to wait for
        releaseLocked(oldest, false, base_ ? base_->error() : std::string("no image folder"));
        continue;
      }
      entries_[oldest].where = Where::kSpilling;
      spill_bytes_ += entries_[oldest].image->data.size();
      spill_queue_.push_back(oldest);
      wake = true;
    }
    // A disk that cannot keep up loses the oldest waiting images rather than the RAM bound.
    const size_t backlog = std::max(budget_, kMinSpillBacklog);
    while (spill_bytes_ > backlog && spill_queue_.size() > 1) {
      const size_t oldest = spill_queue_.front();
      spill_queue_.pop_front();
      spill_bytes_ -= entries_[oldest].image->data.size();
      releaseLocked(oldest, false,
                    "the disk is too slow: more than " + std::to_string(backlog >> 20) +
                        " MB of images wait to be written to ~image_dir");
    }
  }
  if (wake) wake_.notify_one();
}

size_t KeyframeImageCache::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return entries_.size();
}

bool KeyframeImageCache::has(size_t id) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (id >= entries_.size()) return false;
  const Where w = entries_[id].where;
  return w == Where::kMemory || w == Where::kSpilling || w == Where::kDisk;
}

bool KeyframeImageCache::waitSpilled(double timeout) const {
  std::unique_lock<std::mutex> lock(mutex_);
  return spilled_.wait_for(lock, std::chrono::duration<double>(timeout),
                           [this] { return spill_queue_.empty() && !spill_busy_; });
}

sensor_msgs::ImageConstPtr KeyframeImageCache::get(size_t id) const {
  std::string path;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (id >= entries_.size()) return nullptr;
    const Entry& e = entries_[id];
    if (e.where == Where::kMemory || e.where == Where::kSpilling) return e.image;
    if (e.where != Where::kDisk) return nullptr;
    path = fileOf(dir_, id);
  }
  // Read outside the lock: a spilled file is never written again.
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f)
    throw core::IoError("cannot read keyframe image " + std::to_string(id) + " back from '" +
                        path + "': " + std::strerror(errno));
  std::vector<uint8_t> bytes;
  uint8_t chunk[1 << 16];
  size_t got = 0;
  while ((got = std::fread(chunk, 1, sizeof chunk, f)) > 0) bytes.insert(bytes.end(), chunk, chunk + got);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed)
    throw core::IoError("cannot read keyframe image " + std::to_string(id) + " back from '" +
                        path + "'");
  auto image = boost::make_shared<sensor_msgs::Image>();
  try {
    ros::serialization::IStream in(bytes.data(), static_cast<uint32_t>(bytes.size()));
    ros::serialization::deserialize(in, *image);
  } catch (const std::exception& e) {
    throw core::IoError("keyframe image " + std::to_string(id) + " in '" + path +
                        "' is damaged: " + e.what());
  }
  return image;
}

KeyframeImageCache::Stats KeyframeImageCache::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  Stats s;
  s.images = entries_.size();
  s.in_memory = memory_order_.size() + spill_queue_.size() + (spill_busy_ ? 1 : 0);
  s.spilling = spill_queue_.size() + (spill_busy_ ? 1 : 0);
  s.on_disk = on_disk_;
  s.lost = lost_;
  s.memory_bytes = memory_bytes_;
  s.last_error = last_error_;
  return s;
}

std::string KeyframeImageCache::folder() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return dir_;
}

}  // namespace view_selection::ros_node
