#include "view_selection/ros/state_keeper.h"

#include <ros/console.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <sstream>

namespace view_selection::ros_node {

namespace fs = std::filesystem;

namespace {

constexpr double kErrorLogPeriod = 30.0;  // [s, wall] between warnings about failed saves

std::string megabytes(size_t bytes) {
  std::ostringstream s;
  s.precision(bytes < 10 * 1000 * 1000 ? 2 : 0);
  s << std::fixed << static_cast<double>(bytes) / 1e6 << " MB";
  return s.str();
}

}  // namespace

std::string resolveStatePath(const std::string& state_file) {
  if (state_file.empty()) return "";
  const fs::path p(state_file);
  if (p.is_absolute()) return p.lexically_normal().string();
  const char* ros_home = std::getenv("ROS_HOME");
  const char* home = std::getenv("HOME");
  const fs::path base = ros_home && *ros_home ? fs::path(ros_home)
                        : home && *home       ? fs::path(home) / ".ros"
                                              : fs::current_path();
  return (base / p).lexically_normal().string();
}

StateKeeper::StateKeeper(const NodeConfig& config, InputStatistics& statistics,
                         std::string producer)
    : path_(resolveStatePath(config.state_file)),
      statistics_(statistics),
      producer_(std::move(producer)) {
  if (path_.empty()) return;
  std::error_code ec;
  if (fs::exists(path_, ec)) {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      loaded_ = io::readStateFile(path_);
      const double ms =
          1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      ROS_INFO_STREAM("view_selection: read " << loaded_->selector.keyframes.size()
                                              << " keyframes from " << path_ << " in " << ms
                                              << " ms (written by " << loaded_->producer << ")");
    } catch (const core::IoError& e) {
      // Covers StateFileError: truncated, corrupted, foreign, newer. Kept aside, never lost.
      refuseLoaded(e.what());
    }
  } else {
    ROS_INFO_STREAM("view_selection: no state in " << path_ << " yet; starting a new session");
  }
  thread_ = std::thread([this] { loop(); });
}

StateKeeper::~StateKeeper() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  if (aside_) writeAside(*aside_);  // a session a time jump ended is not lost on shutdown
}

std::optional<io::SessionState> StateKeeper::takeLoaded() {
  std::optional<io::SessionState> out = std::move(loaded_);
  loaded_.reset();
  return out;
}

void StateKeeper::refuseLoaded(const std::string& why) {
  loaded_.reset();
  std::string kept;
  try {
    kept = "; the file is kept as " + io::moveAside(path_);
  } catch (const core::IoError& e) {
    // Without the rename the next save would replace it: saving is off for this run then.
    kept = std::string("; could not keep it aside (") + e.what() + "), so this run will not save";
    path_.clear();
  }
  ROS_ERROR_STREAM("view_selection: cannot continue the session in ~state_file: "
                   << why << kept << "; starting empty");
}

void StateKeeper::saveLater(StateSnapshot snapshot) {
  if (!enabled()) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    waiting_ = std::move(snapshot);
  }
  wake_.notify_one();
}

SaveResult StateKeeper::saveNow(StateSnapshot snapshot) {
  if (!enabled()) return {false, "~state_file is empty: the session is not saved", 0, 0.0};
  {
    // A snapshot still waiting is older than this one.
    std::lock_guard<std::mutex> lock(mutex_);
    if (waiting_ && waiting_->sequence <= snapshot.sequence) waiting_.reset();
  }
  return write(snapshot);
}

void StateKeeper::saveAside(StateSnapshot snapshot) {
  if (!enabled()) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    aside_ = std::move(snapshot);
  }
  wake_.notify_one();
}

void StateKeeper::loop() {
  while (true) {
    std::optional<StateSnapshot> aside, snapshot;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stopping_ || waiting_ || aside_; });
      if (stopping_) return;
      aside = std::move(aside_);  // first: the session before the one waiting_ holds
      aside_.reset();
      snapshot = std::move(waiting_);
      waiting_.reset();
    }
    if (aside) writeAside(*aside);
    if (snapshot) write(*snapshot);
  }
}

void StateKeeper::writeAside(StateSnapshot& snapshot) {
  std::lock_guard<std::mutex> lock(write_mutex_);
  const std::string path = previousPath();
  snapshot.state.producer = producer_;
  try {
    std::error_code ec;
    const fs::path folder = fs::path(path).parent_path();
    if (!folder.empty()) fs::create_directories(folder, ec);
    const size_t bytes = io::writeStateFile(path, snapshot.state);
    ROS_INFO_STREAM("view_selection: the session before the time jump ("
                    << snapshot.state.selector.keyframes.size() << " keyframes, "
                    << megabytes(bytes) << ") is kept in " << path);
  } catch (const std::exception& e) {
    ROS_WARN_STREAM("view_selection: keeping the session before the time jump in "
                    << path << " failed: " << e.what());
  }
}

SaveResult StateKeeper::write(StateSnapshot& snapshot) {
  std::lock_guard<std::mutex> lock(write_mutex_);
  SaveResult result;
  if (snapshot.sequence != 0 && snapshot.sequence < written_) {
    result.ok = true;
    result.message = "a later state is on disk already";
    return result;
  }
  const auto t0 = std::chrono::steady_clock::now();
  io::SessionState& state = snapshot.state;
  state.producer = producer_;
  try {
    std::error_code ec;
    const fs::path folder = fs::path(path_).parent_path();
    if (!folder.empty()) fs::create_directories(folder, ec);
    if (ec) throw core::IoError("cannot create folder '" + folder.string() + "': " + ec.message());
    result.bytes = io::writeStateFile(path_, state);
  } catch (const std::exception& e) {
    result.message = std::string("saving the session failed: ") + e.what() +
                     " (the previous state file, if any, is intact)";
    const ros::WallTime now = ros::WallTime::now();
    if (last_error_log_.isZero() || (now - last_error_log_).toSec() >= kErrorLogPeriod) {
      last_error_log_ = now;
      ROS_WARN_STREAM("view_selection: " << result.message);
    }
    return result;
  }
  result.ok = true;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  written_ = std::max(written_, snapshot.sequence);
  const size_t keyframes = state.selector.keyframes.size();
  std::ostringstream s;
  s.precision(1);
  s << std::fixed << "wrote " << keyframes << " keyframes (" << megabytes(result.bytes) << ") to "
    << path_ << " in " << 1e3 * result.seconds << " ms";
  result.message = s.str();
  ROS_DEBUG_STREAM("view_selection: " << result.message);
  const auto& last = state.statistics.last_frame_stamp;
  statistics_.stateSaved(static_cast<uint32_t>(keyframes),
                         last && *last > 0.0 ? ros::Time(*last) : ros::Time());
  return result;
}

}  // namespace view_selection::ros_node
