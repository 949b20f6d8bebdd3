// One online session as it is saved: keyframes, E, the keyframe policy, the point source's own
// state, the statistics. What the state file (session/state_file.h) and its journal
// (session/journal.h) hold; captured from and continued in a ViewSelector by session/capture.h.
#pragma once

#include "view_selection/core/parameters.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/points/feature_point_source.h"
#include "view_selection/points/map_point_source.h"

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace view_selection::session {

/// The node's input counts (its ~statistics), kept with the session they belong to.
struct SessionStatistics {
  uint64_t frames_received = 0;
  uint64_t frames_offered = 0;
  std::map<std::string, uint64_t> dropped;  ///< by reason
  std::string last_error;
  double last_error_stamp = 0.0;  ///< [s]
  double last_insertion_seconds = 0.0;
  double max_insertion_seconds = 0.0;
  /// Stamp of the last frame handled (offered or dropped): a replay continues after it.
  std::optional<double> last_frame_stamp;

  bool operator==(const SessionStatistics& o) const;
};

/// The point source's part of a session.
struct PointSourceState {
  std::string name;     ///< "depth", "features", "map" or "auto"
  core::Params params;  ///< its params() when saved; a source with others cannot continue it
  std::optional<points::MapPointSource::State> map;
  /// "features", and the feature part of "auto" (depth needs no state of its own).
  std::optional<points::FeaturePointSource::State> features;
};

struct SessionState {
  std::string producer;   ///< what wrote it, e.g. "view_selection_node /view_selection"
  double saved_at = 0.0;  ///< [s, Unix time] when the snapshot was taken
  core::ViewSelectorState selector;
  PointSourceState points;
  SessionStatistics statistics;
  /// The node's pair stream (~pairs): the last sequence number it used; absent in files of
  /// select_views and of nodes before the stream.
  std::optional<uint64_t> pair_sequence;
  /// The id of this file as a journal's base (section JRNL): records of a journal beside it
  /// continue it only when they name this id. Absent in files before the journal.
  std::optional<uint64_t> base_id;
  /// (keyframe id, Keyframe::revisit_of) of keyframes this state does not hold whole: a journal
  /// record's (section RVST). In a whole state they are in selector.keyframes and this is empty.
  std::vector<std::pair<core::ViewId, core::ViewId>> revisit_links;
};

/// What changed in a session since an earlier capture: a record of the state journal
/// (`<state file>.journal`, docs/state_file.md). Keyframes and rows are those that are new or
/// changed; the rest (`rest`: config, policy, last stamp, point source, statistics, pair
/// sequence, producer, saved at; its keyframes and rows are empty) is whole.
struct SessionDelta {
  uint64_t keyframe_count = 0;  ///< the session's keyframes after it (fewer: truncated first)
  std::vector<std::pair<core::ViewId, core::Keyframe>> keyframes;            ///< ascending id
  std::vector<std::pair<core::ViewId, std::vector<core::TableEntry>>> rows;  ///< ascending id
  SessionState rest;
};

}  // namespace view_selection::session
