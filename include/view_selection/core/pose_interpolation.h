// Poses between two timed samples: translation linear, rotation by slerp along the shorter arc,
// as tf2 interpolates. Used by the node's topic pose sources (a pose at the image stamp) and by
// tum_to_bag (motion capture at its own rate from a ground-truth trajectory).
#pragma once

#include "view_selection/core/types.h"

#include <vector>

namespace view_selection::core {

/// A pose with its stamp [s].
struct TimedPose {
  double stamp = 0.0;
  CameraPose pose;
};

/// The pose at `stamp` between `a` and `b` (a.stamp <= stamp <= b.stamp is not required: outside
/// it extrapolates linearly, which callers avoid). Equal stamps give `a`. Quaternions are
/// normalised first; the result's quaternion has unit length.
CameraPose interpolatePose(const TimedPose& a, const TimedPose& b, double stamp);

/// The rigid transform a * b (poses as camera-to-world maps: apply b, then a).
CameraPose composePoses(const CameraPose& a, const CameraPose& b);
/// The inverse rigid transform.
CameraPose inversePose(const CameraPose& a);

/// The pose at `stamp` on a trajectory sorted by ascending stamp: interpolated between the two
/// samples around it, held at the first (last) sample before (after) the trajectory. Throws
/// InvalidArgument for an empty trajectory.
CameraPose poseOnTrajectory(const std::vector<TimedPose>& trajectory, double stamp);

}  // namespace view_selection::core
