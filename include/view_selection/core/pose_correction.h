// Loop-closure corrections: a SLAM system republishes its whole corrected trajectory (VINS'
// pose_graph_path, RTAB-Map's mapPath), which carries only its own keyframes. The correction at
// each of them is its corrected pose composed with the inverse of the pose the node had at its
// stamp (the pose source's history, core::PoseHistory), C = corrected * source^-1, a change of
// the world frame. Every keyframe of the node takes the correction at its stamp: between two path
// poses the two corrected poses are interpolated, outside the path the nearest correction holds.
// Only keyframes that moved more than a threshold are changed (their rows and columns of E
// recomputed, ErrorResistanceMatrix::setPoses).
#pragma once

#include "view_selection/core/pose_interpolation.h"
#include "view_selection/core/types.h"

#include <optional>
#include <utility>
#include <vector>

namespace view_selection::core {

struct PoseCorrectionConfig {
  /// [s] a path pose counts when the node has poses (of its frames) on either side of its stamp
  /// within this, to interpolate the pose it had there; otherwise it is skipped.
  double max_source_gap = 0.1;
  double min_translation = 0.002;  ///< [m] a keyframe moves when its centre moves more ...
  double min_rotation_deg = 0.1;   ///< [deg] ... or it turns more than this
};

/// The angle between two orientations [deg].
double rotationDegrees(const CameraPose& a, const CameraPose& b);

/// The corrections along a path (ascending stamp): for each path pose whose `sources` entry (the
/// pose the node had at its stamp) is known, C = path pose * source^-1, at the path pose's stamp.
std::vector<TimedPose> pathCorrections(const std::vector<TimedPose>& path,
                                       const std::vector<std::optional<CameraPose>>& sources);

/// A keyframe as a correction sees it: its current pose, and the pose the source gave it.
struct CorrectableKeyframe {
  double stamp = 0.0;
  CameraPose pose;
  CameraPose source;
};

/// The pose of a keyframe with `source` pose at `stamp` under `corrections` (ascending stamp,
/// not empty): C(t_a) * source and C(t_b) * source interpolated at the stamp between the two path
/// stamps around it; before the first (after the last) the first (last) correction.
CameraPose correctedPose(const std::vector<TimedPose>& corrections, double stamp,
                         const CameraPose& source);

/// Each keyframe the corrections move by more than the thresholds, with its corrected pose.
/// No corrections: no moves.
std::vector<std::pair<ViewId, CameraPose>> matchCorrections(
    const std::vector<CorrectableKeyframe>& keyframes, const std::vector<TimedPose>& corrections,
    const PoseCorrectionConfig& config);

}  // namespace view_selection::core
