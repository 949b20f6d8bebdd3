#include "view_selection/core/pose_correction.h"

#include <algorithm>
#include <cmath>

namespace view_selection::core {

double rotationDegrees(const CameraPose& a, const CameraPose& b) {
  return a.orientation.normalized().angularDistance(b.orientation.normalized()) * 180.0 / M_PI;
}

std::vector<std::pair<ViewId, CameraPose>> matchCorrections(
    const std::vector<TimedPose>& keyframes, const std::vector<TimedPose>& trajectory,
    const PoseCorrectionConfig& config) {
  std::vector<std::pair<ViewId, CameraPose>> moves;
  for (size_t i = 0; i < keyframes.size(); ++i) {
    const double t = keyframes[i].stamp;
    const auto after = std::lower_bound(trajectory.begin(), trajectory.end(), t,
                                        [](const TimedPose& p, double s) { return p.stamp < s; });
    const TimedPose* best = nullptr;
    if (after != trajectory.end()) best = &*after;
    if (after != trajectory.begin() && (!best || t - (after - 1)->stamp <= best->stamp - t))
      best = &*(after - 1);
    if (!best || std::abs(best->stamp - t) > config.stamp_tolerance || !best->pose.isValid())
      continue;
    const CameraPose& old = keyframes[i].pose;
    if ((best->pose.position - old.position).norm() > config.min_translation ||
        rotationDegrees(best->pose, old) > config.min_rotation_deg)
      moves.emplace_back(static_cast<ViewId>(i), best->pose);
  }
  return moves;
}

}  // namespace view_selection::core
