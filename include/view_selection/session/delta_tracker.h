// What changed in a selector since the last save, for a record of the state journal.
#pragma once

#include "view_selection/core/view_selector.h"
#include "view_selection/session/session_state.h"

#include <cstddef>
#include <cstdint>

namespace view_selection::session {

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
  size_t saved_ = 0;                           // keyframes at the last capture
  uint64_t row_mark_ = 0, keyframe_mark_ = 0;  // the last versions issued then
};

}  // namespace view_selection::session
