// Loop-closure corrections: a SLAM system republishes its whole corrected trajectory (VINS'
// pose_graph_path, RTAB-Map's mapPath); each keyframe takes the pose of that trajectory at its
// stamp, and only keyframes that moved more than a threshold are changed (their rows and columns
// of E recomputed, ErrorResistanceMatrix::setPoses).
#pragma once

#include "view_selection/core/pose_interpolation.h"
#include "view_selection/core/types.h"

#include <utility>
#include <vector>

namespace view_selection::core {

struct PoseCorrectionConfig {
  double stamp_tolerance = 0.01;   ///< [s] a trajectory pose this close to a keyframe's stamp
  double min_translation = 0.002;  ///< [m] a keyframe moves when its centre moves more ...
  double min_rotation_deg = 0.1;   ///< [deg] ... or it turns more than this
};

/// The angle between two orientations [deg].
double rotationDegrees(const CameraPose& a, const CameraPose& b);

/// For each keyframe (stamp, pose), the trajectory pose nearest its stamp within the tolerance
/// (`trajectory` ascending by stamp, optical-frame poses); a keyframe it moves by more than the
/// thresholds is returned with that pose. Keyframes the trajectory does not cover keep theirs.
std::vector<std::pair<ViewId, CameraPose>> matchCorrections(
    const std::vector<TimedPose>& keyframes, const std::vector<TimedPose>& trajectory,
    const PoseCorrectionConfig& config);

}  // namespace view_selection::core
