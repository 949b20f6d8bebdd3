// ~state_file: reads the saved session at start (a bad file is kept aside with one clear error)
// and writes snapshots of the session on a thread of its own, so that a save never holds up the
// frames: the worker copies its state under its lock and hands the copy over.
#pragma once

#include "view_selection/session/journal.h"
#include "view_selection/session/session_state.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/node_config.h"

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace view_selection::ros_node {

/// One snapshot of the session; `sequence` orders snapshots (a later one is never replaced by an
/// earlier one on disk).
struct StateSnapshot {
  uint64_t sequence = 0;
  session::SessionState state;
};

/// What changed since the capture `follows` (a snapshot or a journal record), as one record of
/// the state journal; `sequence` is its own capture's.
struct JournalSnapshot {
  uint64_t sequence = 0;
  uint64_t follows = 0;
  session::SessionDelta delta;
};

/// What a save did.
struct SaveResult {
  bool ok = false;
  std::string message;  ///< "wrote 37 keyframes (1.8 MB) to ... in 12 ms", or why not
  size_t bytes = 0;
  double seconds = 0.0;
};

class StateKeeper {
 public:
  /// With an empty ~state_file, does nothing. Otherwise resolves the path (relative to ROS_HOME,
  /// default ~/.ros) and reads the file if it exists; `producer` is written into every save.
  StateKeeper(const NodeConfig& config, InputStatistics& statistics, std::string producer);
  /// Writes what still waits (a snapshot, a journal record, a time jump's session), then joins
  /// the thread.
  ~StateKeeper();
  StateKeeper(const StateKeeper&) = delete;
  StateKeeper& operator=(const StateKeeper&) = delete;

  bool enabled() const { return !path_.empty(); }
  const std::string& path() const { return path_; }
  /// The session read at start (once; empty afterwards, without a file or when it was bad).
  std::optional<session::SessionState> takeLoaded();
  /// The loaded session cannot continue here (another point source, inconsistent content): logs
  /// `why` once, keeps the file aside (it is never overwritten) and the node starts empty.
  void refuseLoaded(const std::string& why);

  /// Called with the result once a snapshot is written (or a later one that holds it).
  using SaveDone = std::function<void(const SaveResult&)>;
  /// Queues a snapshot for the keeper's thread; one still waiting is replaced (its `done` then
  /// follows the new one). Never blocks on a write. `done` runs on the keeper's thread.
  void saveLater(StateSnapshot snapshot, SaveDone done = {});
  /// Writes now, after a write in progress (~save_state, shutdown).
  SaveResult saveNow(StateSnapshot snapshot);
  /// Whether the next save must be a whole snapshot (saveLater/saveNow): no base file with a
  /// journal id yet, or the journal's chain broke (a failed write, a snapshot written out of
  /// order). Otherwise the worker hands over only what changed (appendLater).
  bool wantsFull() const { return need_full_.load(); }
  /// Queues a journal record for the keeper's thread, merged with one still waiting. Never
  /// blocks on a write. The record is appended (O(its size)) when it follows what is on disk;
  /// otherwise it is dropped and wantsFull() turns true.
  void appendLater(JournalSnapshot record);
  /// Appends now, after a write in progress (shutdown); not ok when it could not (then save a
  /// whole snapshot).
  SaveResult appendNow(JournalSnapshot record);
  /// A session a time jump ended: written to previousPath() by the keeper's thread (replacing
  /// the one kept there before), and on destruction when it is still waiting. Never blocks on a
  /// write.
  void saveAside(StateSnapshot snapshot);
  /// Where saveAside writes: the state file's path + kPreviousSuffix.
  std::string previousPath() const { return path_ + kPreviousSuffix; }
  static constexpr const char* kPreviousSuffix = ".previous";

 private:
  void loop();
  SaveResult write(StateSnapshot& snapshot);
  SaveResult append(JournalSnapshot& record);
  /// Base + journal read back and written as a new base; the journal emptied. Under write_mutex_.
  void compactLocked();
  /// After a new base is on disk: the journal emptied (its records name the old base).
  void startJournalLocked(uint64_t base_id, size_t base_bytes);
  std::string journalPath() const { return session::journalPath(path_); }
  void writeAside(StateSnapshot& snapshot);

  std::string path_;
  InputStatistics& statistics_;
  std::string producer_;
  std::optional<session::SessionState> loaded_;

  std::mutex write_mutex_;  // one write at a time; guards written_
  uint64_t written_ = 0;    // sequence of the last snapshot or record on disk
  std::optional<uint64_t> base_id_;  // of the base file on disk that the journal follows
  uint64_t journal_index_ = 0;       // of the next record
  size_t journal_bytes_ = 0, base_bytes_ = 0;
  std::atomic<bool> need_full_{true};
  ros::WallTime last_error_log_;

  std::mutex mutex_;
  std::condition_variable wake_;
  std::optional<StateSnapshot> waiting_;
  std::vector<SaveDone> waiting_done_;  // to call once waiting_ (or a later snapshot) is written
  std::optional<JournalSnapshot> waiting_record_;
  std::optional<StateSnapshot> aside_;  // saveAside() not yet written
  bool stopping_ = false;
  std::thread thread_;  // last
};

/// ~state_file resolved: "" stays "", an absolute path is kept, a relative one is taken relative
/// to $ROS_HOME (else $HOME/.ros).
std::string resolveStatePath(const std::string& state_file);

}  // namespace view_selection::ros_node
