#include "view_selection/session/delta_tracker.h"

#include "view_selection/session/capture.h"

#include <algorithm>

namespace view_selection::session {

void DeltaTracker::markSaved(const core::ViewSelector& selector) {
  saved_ = selector.matrix().size();
  row_mark_ = core::ErrorResistanceTable::lastVersionIssued();
  keyframe_mark_ = core::ErrorResistanceMatrix::lastKeyframeVersionIssued();
}

SessionDelta DeltaTracker::capture(const core::ViewSelector& selector) {
  const core::ErrorResistanceMatrix& m = selector.matrix();
  const core::ErrorResistanceTable& table = m.table();
  const size_t n = m.size();
  const uint64_t row_mark = core::ErrorResistanceTable::lastVersionIssued();
  const uint64_t keyframe_mark = core::ErrorResistanceMatrix::lastKeyframeVersionIssued();
  SessionDelta d;
  d.keyframe_count = n;
  constexpr size_t kChunk = core::ErrorResistanceTable::kVersionChunk;
  const size_t saved = std::min(n, saved_);  // new ones from here on, always
  for (size_t c = 0; c * kChunk < n; ++c) {
    const size_t end = std::min(n, (c + 1) * kChunk);
    if (end <= saved && table.chunkVersion(c) <= row_mark_ &&
        m.keyframeChunkVersion(c) <= keyframe_mark_)
      continue;  // nothing in it changed
    for (size_t i = c * kChunk; i < end; ++i) {
      const auto id = static_cast<core::ViewId>(i);
      if (i >= saved || m.keyframeVersion(id) > keyframe_mark_)
        d.keyframes.emplace_back(id, m.keyframe(id));
      if (i >= saved || table.rowVersion(id) > row_mark_) d.rows.emplace_back(id, table.row(id));
    }
  }
  saved_ = n;
  row_mark_ = row_mark;
  keyframe_mark_ = keyframe_mark;
  d.rest.selector.config = selector.config();
  d.rest.selector.policy = selector.policyState();
  d.rest.selector.last_stamp = selector.lastStamp();
  d.rest.points = capturePointSource(selector.pointSource());
  return d;
}

}  // namespace view_selection::session
