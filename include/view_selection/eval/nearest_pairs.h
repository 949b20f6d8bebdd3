// The "nearest" baseline: pairs from poses alone, as commonly done before matching (for example
// hloc's pairs_from_poses): each view is paired with its k nearest camera centres among the
// views whose optical axis is within a viewing-angle limit of its own.
#pragma once

#include "view_selection/core/types.h"

#include <utility>
#include <vector>

namespace view_selection::eval {

struct NearestPairsConfig {
  int k = 5;                         ///< neighbours per view
  double max_view_angle_deg = 30.0;  ///< angle between optical axes; 180 disables the limit
  void validate() const;             ///< throws InvalidArgument
};

/// For each view i: the views j != i with angle(axis_i, axis_j) <= max_view_angle_deg, sorted by
/// (|O_i - O_j|, j), first k. Deterministic: ties break on the lower id.
std::vector<std::vector<core::ViewId>> nearestNeighbourSets(
    const std::vector<core::CameraPose>& poses, const NearestPairsConfig& config);

/// The undirected, de-duplicated union of nearestNeighbourSets as (i, j), i < j, sorted; the
/// same form as Selection::pairs, so writePairsTxt takes it. Throws InvalidArgument for an
/// invalid pose or config.
std::vector<std::pair<core::ViewId, core::ViewId>> nearestPairs(
    const std::vector<core::CameraPose>& poses, const NearestPairsConfig& config);

}  // namespace view_selection::eval
