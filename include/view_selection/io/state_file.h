// The state file: one online session (keyframes, E, the keyframe policy, the point source, the
// statistics) saved so that a restarted node, or select_views --state, continues it exactly.
// The byte layout is in docs/state_file.md; a file is written atomically (io/atomic_file.h).
#pragma once

#include "view_selection/core/exceptions.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/points/feature_point_source.h"
#include "view_selection/points/map_point_source.h"

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace view_selection::io {

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
};

/// What changed in a session since an earlier capture: a record of the state journal
/// (`<state file>.journal`, docs/state_file.md). Keyframes and rows are those that are new or
/// changed; the rest (`rest`: config, policy, last stamp, point source, statistics, pair
/// sequence, producer, saved at; its keyframes and rows are empty) is whole.
struct SessionDelta {
  uint64_t keyframe_count = 0;  ///< the session's keyframes after it (fewer: truncated first)
  std::vector<std::pair<core::ViewId, core::Keyframe>> keyframes;           ///< ascending id
  std::vector<std::pair<core::ViewId, std::vector<core::TableEntry>>> rows;  ///< ascending id
  SessionState rest;
};

/// Applies `delta` to `state`; afterwards `state` equals the session the delta was captured
/// from. Throws StateFileError when it does not fit (a new keyframe or row missing, an id out of
/// range); `state` is unchanged then.
void applyDelta(SessionState& state, const SessionDelta& delta);
/// `earlier` followed by `later`, as one delta.
void mergeDelta(SessionDelta& earlier, SessionDelta later);

/// Captures what changed in a selector since the last capture: rows and keyframes whose versions
/// (ErrorResistanceTable::rowVersion, ErrorResistanceMatrix::keyframeVersion) were issued after
/// it, found chunk by chunk (O(n / 256) plus the chunks that changed), and the new ones. Call it
/// under the selector's lock.
class DeltaTracker {
 public:
  /// Everything the selector holds now counts as saved.
  void markSaved(const core::ViewSelector& selector);
  /// What changed since markSaved() or the last capture (then counts as saved). The point
  /// source's state is whole (empty for "depth").
  SessionDelta capture(const core::ViewSelector& selector);

 private:
  size_t saved_ = 0;  // keyframes at the last capture
  uint64_t row_mark_ = 0, keyframe_mark_ = 0;  // the last versions issued then
};

/// One record of a journal: follows the base with id `base_id`, `index` counting from 0 after
/// it. Layout in docs/state_file.md (a length and CRC-32s, so a torn tail is found).
std::vector<uint8_t> encodeJournalRecord(uint64_t base_id, uint64_t index,
                                         const SessionDelta& delta);

/// A journal read against its base.
struct JournalReplay {
  uint64_t records = 0;      ///< applied
  uint64_t stale = 0;        ///< of another base (an older one, before a compaction): ignored
  size_t good_bytes = 0;     ///< the prefix that holds complete records (append after it)
  size_t total_bytes = 0;
  std::string error;         ///< why the tail from good_bytes on was dropped; empty: none
};
/// Applies the records of `data` that follow `state.base_id` to `state`, in order, up to the
/// first torn or corrupt record (reported in `error`, never thrown).
JournalReplay replayJournal(SessionState& state, const uint8_t* data, size_t size,
                            const std::string& name = "");
/// `path` + ".journal".
std::string journalPath(const std::string& path);
/// The state file with its journal applied (readStateFile, then replayJournal when the journal
/// exists). `replay` (optional) says what the journal gave.
SessionState readSession(const std::string& path, JournalReplay* replay = nullptr);
/// Appends `bytes` to the file (made when missing) and flushes it to disk (fdatasync). Throws
/// core::IoError; the file may then end in a torn record, which readers drop.
void appendToFile(const std::string& path, const std::vector<uint8_t>& bytes);
/// Cuts the file to `size` bytes (made empty when missing) and flushes it. Throws core::IoError.
void truncateFile(const std::string& path, size_t size);

/// A state file that cannot be used: truncated, corrupted, foreign, or of a newer format. The
/// message says which, and names the file when it came from one.
class StateFileError : public core::IoError {
 public:
  using core::IoError::IoError;
};

/// The selector's and its point source's state, copied (call it under the lock that guards the
/// selector; it copies points and shares depth maps and descriptors, which are never written).
SessionState captureSession(const core::ViewSelector& selector);
/// Continues `selector` from `state` (keyframes, E and the policy as saved, the point source's
/// tracks or map). Throws core::InvalidArgument when `state` was made with another point source
/// or other point-source parameters (nothing changes then), core::InvalidInput when it is
/// inconsistent (`selector` is reset then: empty). The selector's config becomes the saved one; apply another with
/// ViewSelector::setConfig afterwards.
void restoreSession(core::ViewSelector& selector, const SessionState& state);

/// The current format version; readers accept this one and older ones.
inline constexpr uint32_t kStateFormatVersion = 1;

std::vector<uint8_t> encodeState(const SessionState& state);
/// Throws StateFileError naming what is wrong (and `name`, when given, in the message).
SessionState decodeState(const uint8_t* data, size_t size, const std::string& name = "");
/// Writes atomically (a crash leaves the old complete file or the new one); returns the size in
/// bytes. Throws core::IoError (nothing is left behind then).
size_t writeStateFile(const std::string& path, const SessionState& state);
/// Throws core::IoError when the file cannot be read, StateFileError when its content is bad.
SessionState readStateFile(const std::string& path);
/// A selector (with the saved point source and its parameters, the saved method parameters)
/// that continues `state`: what select_views --state re-selects from. Throws
/// core::InvalidArgument / core::InvalidInput for a state that cannot be continued.
std::unique_ptr<core::ViewSelector> selectorFor(const SessionState& state);

/// Renames a bad state file aside, to "<path>.bad-<UTC YYYYmmddTHHMMSS>[-n]", never over an
/// existing file. Returns the new path; throws core::IoError when the rename fails.
std::string moveAside(const std::string& path);

/// CRC-32 (IEEE 802.3, as zlib's crc32()) of `size` bytes, continuing from `crc`.
uint32_t crc32(const uint8_t* data, size_t size, uint32_t crc = 0);

}  // namespace view_selection::io
