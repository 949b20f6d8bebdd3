#include "view_selection/ros/state_keeper.h"

#include "view_selection/io/file_ops.h"
#include "view_selection/session/state_file.h"

#include <ros/console.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <sstream>

namespace view_selection::ros_node {

namespace fs = std::filesystem;

namespace {

constexpr double kErrorLogPeriod = 30.0;  // [s, wall] between warnings about failed saves
// The journal is compacted (written into a new base) once it outgrows the base and this.
constexpr size_t kMinCompactBytes = 4 * 1000 * 1000;

/// A base id no earlier base had (random, non-zero).
uint64_t newBaseId() {
  static std::mt19937_64 random{std::random_device{}() ^
                                static_cast<uint64_t>(
                                    std::chrono::steady_clock::now().time_since_epoch().count())};
  uint64_t id = 0;
  while (id == 0) id = random();
  return id;
}

size_t fileSize(const std::string& path) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  return ec ? 0 : static_cast<size_t>(size);
}

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
      session::JournalReplay replay;
      loaded_ = session::readSession(path_, &replay);
      const double ms =
          1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (!replay.error.empty())
        ROS_ERROR_STREAM("view_selection: the state journal ends in a torn or damaged record: "
                         << replay.error << "; continuing from the last good record ("
                         << replay.records << " records after the base)");
      ROS_INFO_STREAM("view_selection: read " << loaded_->selector.keyframes.size()
                                              << " keyframes from " << path_ << " and "
                                              << replay.records << " journal records in " << ms
                                              << " ms (written by " << loaded_->producer << ")");
      base_bytes_ = fileSize(path_);
      if (loaded_->base_id) {
        base_id_ = loaded_->base_id;
        journal_index_ = replay.records;
        journal_bytes_ = replay.good_bytes;
        need_full_ = false;
        // Later records go right after the last good one.
        if (replay.good_bytes != replay.total_bytes) {
          try {
            io::truncateFile(journalPath(), replay.good_bytes);
          } catch (const core::IoError& e) {
            ROS_WARN_STREAM("view_selection: " << e.what() << "; the next save is a whole one");
            need_full_ = true;
          }
        }
      }
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

std::optional<session::SessionState> StateKeeper::takeLoaded() {
  std::optional<session::SessionState> out = std::move(loaded_);
  loaded_.reset();
  return out;
}

void StateKeeper::refuseLoaded(const std::string& why) {
  loaded_.reset();
  std::string kept;
  std::lock_guard<std::mutex> lock(write_mutex_);
  base_id_.reset();
  need_full_ = true;
  try {
    const std::string aside = io::moveAside(path_);
    kept = "; the file is kept as " + aside;
    // Its journal with it (a new base would make its records stale).
    std::error_code ec;
    if (fs::exists(journalPath(), ec)) {
      fs::rename(journalPath(), session::journalPath(aside), ec);
      if (!ec) kept += " (its journal as " + session::journalPath(aside) + ")";
    }
  } catch (const core::IoError& e) {
    // Without the rename the next save would replace it: saving is off for this run then.
    kept = std::string("; could not keep it aside (") + e.what() + "), so this run will not save";
    path_.clear();
  }
  ROS_ERROR_STREAM("view_selection: cannot continue the session in ~state_file: "
                   << why << kept << "; starting empty");
}

void StateKeeper::saveLater(StateSnapshot snapshot, SaveDone done) {
  if (!enabled()) {
    if (done) done({false, "~state_file is empty: the session is not saved", 0, 0.0});
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // A record waiting is older: the snapshot holds it.
    if (waiting_record_ && waiting_record_->sequence <= snapshot.sequence) waiting_record_.reset();
    waiting_ = std::move(snapshot);
    if (done) waiting_done_.push_back(std::move(done));
  }
  wake_.notify_one();
}

SaveResult StateKeeper::saveNow(StateSnapshot snapshot) {
  if (!enabled()) return {false, "~state_file is empty: the session is not saved", 0, 0.0};
  std::vector<SaveDone> done;
  {
    // A snapshot or record still waiting is older than this one.
    std::lock_guard<std::mutex> lock(mutex_);
    if (waiting_ && waiting_->sequence <= snapshot.sequence) {
      waiting_.reset();
      done.swap(waiting_done_);  // this save holds what they waited for
    }
    if (waiting_record_ && waiting_record_->sequence <= snapshot.sequence) waiting_record_.reset();
  }
  const SaveResult result = write(snapshot);
  for (const SaveDone& d : done) d(result);
  return result;
}

void StateKeeper::appendLater(JournalSnapshot record) {
  if (!enabled()) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (waiting_record_ && waiting_record_->sequence == record.follows) {
      // One record for both: what the first follows, what the second leads to.
      const uint64_t follows = waiting_record_->follows;
      session::mergeDelta(waiting_record_->delta, std::move(record.delta));
      waiting_record_->sequence = record.sequence;
      waiting_record_->follows = follows;
    } else {
      waiting_record_ = std::move(record);
    }
  }
  wake_.notify_one();
}

SaveResult StateKeeper::appendNow(JournalSnapshot record) {
  if (!enabled()) return {false, "~state_file is empty: the session is not saved", 0, 0.0};
  std::optional<JournalSnapshot> earlier;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    earlier = std::move(waiting_record_);
    waiting_record_.reset();
  }
  if (earlier && earlier->sequence == record.follows) {
    const uint64_t follows = earlier->follows;
    session::mergeDelta(earlier->delta, std::move(record.delta));
    earlier->sequence = record.sequence;
    earlier->follows = follows;
    return append(*earlier);
  }
  return append(record);
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
    std::optional<JournalSnapshot> record;
    std::vector<SaveDone> done;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stopping_ || waiting_ || aside_ || waiting_record_; });
      // On stop, what still waits is written first: a capture handed over is the only copy
      // of what changed since the save before it (the worker's shutdown save only adds to it).
      if (stopping_ && !waiting_ && !aside_ && !waiting_record_) return;
      aside = std::move(aside_);  // first: the session before the one waiting_ holds
      aside_.reset();
      snapshot = std::move(waiting_);
      waiting_.reset();
      done.swap(waiting_done_);
      record = std::move(waiting_record_);
      waiting_record_.reset();
    }
    if (aside) writeAside(*aside);
    if (snapshot) {
      const SaveResult result = write(*snapshot);
      for (const SaveDone& d : done) d(result);
    }
    if (record && (!snapshot || record->sequence > snapshot->sequence)) append(*record);
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
    const size_t bytes = session::writeStateFile(path, snapshot.state);
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
  session::SessionState& state = snapshot.state;
  state.producer = producer_;
  const uint64_t base_id = newBaseId();
  state.base_id = base_id;
  try {
    std::error_code ec;
    const fs::path folder = fs::path(path_).parent_path();
    if (!folder.empty()) fs::create_directories(folder, ec);
    if (ec) throw core::IoError("cannot create folder '" + folder.string() + "': " + ec.message());
    result.bytes = session::writeStateFile(path_, state);
    // The base is on disk first: the journal's records name the old one, so a crash before the
    // journal is emptied leaves records a reader ignores.
    startJournalLocked(base_id, result.bytes);
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

void StateKeeper::startJournalLocked(uint64_t base_id, size_t base_bytes) {
  base_id_ = base_id;
  base_bytes_ = base_bytes;
  journal_index_ = 0;
  try {
    io::truncateFile(journalPath(), 0);
    journal_bytes_ = 0;
    need_full_ = false;
  } catch (const core::IoError& e) {
    // Its stale records are ignored, but a torn one at its end would hide later records.
    need_full_ = true;
    ROS_WARN_STREAM("view_selection: " << e.what() << "; the next save is a whole one again");
  }
}

SaveResult StateKeeper::append(JournalSnapshot& record) {
  std::lock_guard<std::mutex> lock(write_mutex_);
  SaveResult result;
  if (record.sequence <= written_) {  // a whole snapshot written since holds it
    result.ok = true;
    result.message = "a later state is on disk already";
    return result;
  }
  if (need_full_ || !base_id_ || record.follows != written_) {
    need_full_ = true;
    result.message = "the journal does not follow the file on disk; the next save is a whole one";
    return result;
  }
  const auto t0 = std::chrono::steady_clock::now();
  record.delta.rest.producer = producer_;
  const std::vector<uint8_t> bytes = session::encodeJournalRecord(*base_id_, journal_index_, record.delta);
  try {
    io::appendToFile(journalPath(), bytes);
  } catch (const std::exception& e) {
    need_full_ = true;  // the journal may end in a torn record now
    result.message = std::string("saving the session failed: ") + e.what() +
                     " (the state on disk is intact up to the previous save)";
    const ros::WallTime now = ros::WallTime::now();
    if (last_error_log_.isZero() || (now - last_error_log_).toSec() >= kErrorLogPeriod) {
      last_error_log_ = now;
      ROS_WARN_STREAM("view_selection: " << result.message);
    }
    return result;
  }
  ++journal_index_;
  journal_bytes_ += bytes.size();
  written_ = record.sequence;
  result.ok = true;
  result.bytes = bytes.size();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const session::SessionDelta& d = record.delta;
  std::ostringstream s;
  s.precision(1);
  s << std::fixed << "appended " << d.keyframes.size() << " keyframes and " << d.rows.size()
    << " rows (" << megabytes(result.bytes) << ", " << d.keyframe_count << " keyframes in all) to "
    << journalPath() << " in " << 1e3 * result.seconds << " ms";
  result.message = s.str();
  ROS_DEBUG_STREAM("view_selection: " << result.message);
  const auto& last = d.rest.statistics.last_frame_stamp;
  statistics_.stateSaved(static_cast<uint32_t>(d.keyframe_count),
                         last && *last > 0.0 ? ros::Time(*last) : ros::Time());
  if (journal_bytes_ > std::max(base_bytes_, kMinCompactBytes)) compactLocked();
  return result;
}

void StateKeeper::compactLocked() {
  const auto t0 = std::chrono::steady_clock::now();
  try {
    session::JournalReplay replay;
    session::SessionState state = session::readSession(path_, &replay);
    if (!replay.error.empty() || replay.records != journal_index_)
      throw core::IoError("the journal read back is not what was written (" +
                          (replay.error.empty() ? std::to_string(replay.records) + " records"
                                                : replay.error) +
                          ")");
    const uint64_t base_id = newBaseId();
    state.base_id = base_id;
    const size_t bytes = session::writeStateFile(path_, state);
    startJournalLocked(base_id, bytes);
    ROS_DEBUG_STREAM("view_selection: state journal compacted into "
                     << path_ << " (" << megabytes(bytes) << ") in "
                     << 1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0)
                                  .count()
                     << " ms");
  } catch (const std::exception& e) {
    // Base and journal on disk are still whole; a whole save next starts them over.
    need_full_ = true;
    ROS_WARN_STREAM("view_selection: compacting the state journal failed: " << e.what());
  }
}

}  // namespace view_selection::ros_node
