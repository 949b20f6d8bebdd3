#include "view_selection/ros/session_handoff.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/parameters.h"
#include "view_selection/session/capture.h"

#include <ros/console.h>

namespace view_selection::ros_node {

SessionHandoff::SessionHandoff(const NodeConfig& config, StateKeeper& keeper,
                               InputStatistics& statistics, PairStream* pairs)
    : config_(config), keeper_(keeper), statistics_(statistics), pairs_(pairs) {}

std::optional<session::SessionState> SessionHandoff::continueLoaded(
    core::ViewSelector& selector, const core::ViewSelectorConfig& wanted_config) {
  std::optional<session::SessionState> loaded = keeper_.takeLoaded();
  if (!loaded) return std::nullopt;
  try {
    session::restoreSession(selector, *loaded);
    saved_.markSaved(selector);  // what the file holds; a reconfigure below changes rows
    // The node's parameters win over the saved ones, as a live reconfigure would apply them
    // (compared as they act: the saved ones are the values in force, the gate's preset applied).
    core::ViewSelectorConfig wanted = wanted_config;
    wanted.matrix.applyGate();
    if (core::paramsOf(selector.config()) != core::paramsOf(wanted)) {
      ROS_INFO(
          "view_selection: the saved session used other method parameters; applying this "
          "node's (the matrix is recomputed where its gates changed)");
      selector.setConfig(wanted_config);
    }
  } catch (const core::Error& e) {
    selector.reset();
    keeper_.refuseLoaded(e.what());
    return std::nullopt;
  }
  // The restored session counts as saved: the file holds it.
  changed_since_save_ = false;
  return loaded;
}

StateSnapshot SessionHandoff::captureWhole(const core::ViewSelector& selector) {
  StateSnapshot s;
  s.sequence = ++captures_;
  s.state = session::captureSession(selector);
  s.state.statistics = statistics_.toSaved();
  s.state.saved_at = ros::WallTime::now().toSec();
  if (pairs_) s.state.pair_sequence = pairs_->sequence();
  saved_.markSaved(selector);
  changed_since_save_ = false;
  return s;
}

JournalSnapshot SessionHandoff::captureDelta(const core::ViewSelector& selector) {
  JournalSnapshot j;
  j.follows = captures_;
  j.sequence = ++captures_;
  j.delta = saved_.capture(selector);
  j.delta.rest.statistics = statistics_.toSaved();
  j.delta.rest.saved_at = ros::WallTime::now().toSec();
  if (pairs_) j.delta.rest.pair_sequence = pairs_->sequence();
  changed_since_save_ = false;
  return j;
}

void SessionHandoff::keyframeInserted(const core::ViewSelector& selector) {
  if (config_.autosave_keyframes > 0 && ++keyframes_since_save_ >= config_.autosave_keyframes &&
      keeper_.enabled()) {
    keyframes_since_save_ = 0;
    // Only what changed since the last save, appended to the journal on the keeper's thread;
    // a whole copy when the journal cannot continue (no base yet, a failed write).
    if (keeper_.wantsFull())
      keeper_.saveLater(captureWhole(selector));
    else
      keeper_.appendLater(captureDelta(selector));
  }
}

void SessionHandoff::keepAside(uint64_t generation) {
  if (!keeper_.enabled()) return;
  std::lock_guard<std::mutex> lock(aside_mutex_);
  // Frames of the old session still queued are discarded: its statistics are final here.
  if (!aside_) aside_ = Aside{generation, statistics_.toSaved()};
}

void SessionHandoff::beforeClear(const core::ViewSelector& selector, uint64_t generation) {
  std::optional<Aside> aside;
  {
    std::lock_guard<std::mutex> lock(aside_mutex_);
    aside = std::move(aside_);
    aside_.reset();
  }
  // Only when the selector holds that session still (no ~reset came between).
  if (aside && aside->generation == generation) {
    StateSnapshot old = captureWhole(selector);
    old.state.statistics = aside->statistics;
    keeper_.saveAside(std::move(old));
  }
}

void SessionHandoff::afterClear(const core::ViewSelector& selector) {
  keyframes_since_save_ = 0;
  keeper_.saveLater(captureWhole(selector));
}

void SessionHandoff::saveOnShutdown(const core::ViewSelector& selector,
                                    std::timed_mutex& state_mutex) {
  if (!keeper_.enabled()) return;
  std::optional<JournalSnapshot> record;
  std::optional<StateSnapshot> last;
  {
    std::lock_guard<std::timed_mutex> lock(state_mutex);
    if (changed_since_save_) {
      if (keeper_.wantsFull())
        last = captureWhole(selector);
      else
        record = captureDelta(selector);
    }
  }
  if (record) {
    const SaveResult appended = keeper_.appendNow(std::move(*record));
    if (appended.ok) {
      ROS_INFO_STREAM("view_selection: session saved on shutdown: " << appended.message);
      return;
    }
    std::lock_guard<std::timed_mutex> lock(state_mutex);
    last = captureWhole(selector);  // the journal could not continue: a whole save
  }
  if (!last) return;
  const SaveResult saved = keeper_.saveNow(std::move(*last));
  if (saved.ok)
    ROS_INFO_STREAM("view_selection: session saved on shutdown: " << saved.message);
  else
    ROS_ERROR_STREAM("view_selection: " << saved.message);
}

}  // namespace view_selection::ros_node
