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
};

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
