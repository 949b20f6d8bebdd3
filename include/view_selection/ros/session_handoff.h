// The worker's persistence hand-off (~state_file): what of the session the worker gives the
// state keeper, and when. Under the worker's state lock it copies the session, whole or only
// what changed since the last save (session::DeltaTracker), and hands the copy to the keeper, whose
// thread writes it; the worker goes on at once. It writes on the calling thread only on
// shutdown, when the worker's thread is gone. A time jump's old session waits here, under the
// aside lock, until the worker clears it and hands it to the keeper.
#pragma once

#include "view_selection/core/view_selector.h"
#include "view_selection/session/delta_tracker.h"
#include "view_selection/session/session_state.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/pair_stream.h"
#include "view_selection/ros/state_keeper.h"

#include <atomic>
#include <cstdint>
#include <mutex>
#include <optional>

namespace view_selection::ros_node {

class SessionHandoff {
 public:
  /// `pairs`: the pair stream whose sequence a save keeps, or null.
  SessionHandoff(const NodeConfig& config, StateKeeper& keeper, InputStatistics& statistics,
                 PairStream* pairs);

  bool enabled() const { return keeper_.enabled(); }
  /// Something a saved session would differ in happened (a keyframe, a drop, a reconfigure).
  /// Any thread.
  void markChanged() { changed_since_save_ = true; }

  // Under the worker's state lock (the selector is the one it guards):

  /// Continues in `selector` the session the keeper read at start, if any, and applies `wanted`
  /// (the node's method parameters) over the saved ones. Returns the session continued; nullopt
  /// without one, or when it cannot continue (the keeper keeps the file aside; `selector` is
  /// empty then).
  std::optional<session::SessionState> continueLoaded(core::ViewSelector& selector,
                                                 const core::ViewSelectorConfig& wanted);
  /// The whole session now (it counts as saved from here on).
  StateSnapshot captureWhole(const core::ViewSelector& selector);
  /// What changed since the last capture, for the state journal (O(changed) but the version
  /// scan).
  JournalSnapshot captureDelta(const core::ViewSelector& selector);
  /// After each keyframe: every ~autosave_keyframes, what changed (the whole session when the
  /// journal cannot continue) goes to the keeper's thread.
  void keyframeInserted(const core::ViewSelector& selector);
  /// Before the selector, which still holds generation `generation`, is cleared for a new one:
  /// when a time jump ended that generation, its session goes to <state_file>.previous.
  void beforeClear(const core::ViewSelector& selector, uint64_t generation);
  /// After it was cleared: the empty session is saved (so that a crash after a reset does not
  /// bring back the old one), and the autosave count starts again.
  void afterClear(const core::ViewSelector& selector);

  /// A time jump ends generation `generation`: its session, with the statistics as they are
  /// now, is kept aside until the worker clears it (the first one pending wins). Any thread;
  /// takes the aside lock.
  void keepAside(uint64_t generation);

  /// On shutdown, after the worker's thread is gone: what changed since the last save is
  /// written now, on this thread (appended to the journal, or whole when the journal cannot
  /// continue). Takes `state_mutex`, the worker's state lock, to copy it.
  void saveOnShutdown(const core::ViewSelector& selector, std::timed_mutex& state_mutex);

 private:
  const NodeConfig& config_;
  StateKeeper& keeper_;
  InputStatistics& statistics_;
  PairStream* pairs_;

  // Under the worker's state lock.
  uint64_t captures_ = 0;         // state snapshots taken (their sequence)
  int keyframes_since_save_ = 0;  // towards ~autosave_keyframes
  session::DeltaTracker saved_;        // what the last capture held
  std::atomic<bool> changed_since_save_{false};  // anything a saved session would differ in

  // A time jump's old session, to be kept in <state_file>.previous when the worker clears it:
  // the generation it belonged to and its statistics at the jump.
  struct Aside {
    uint64_t generation = 0;
    session::SessionStatistics statistics;
  };
  std::mutex aside_mutex_;  // the aside lock
  std::optional<Aside> aside_;
};

}  // namespace view_selection::ros_node
