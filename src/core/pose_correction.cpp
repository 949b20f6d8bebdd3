#include "view_selection/core/pose_correction.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>

namespace view_selection::core {

double rotationDegrees(const CameraPose& a, const CameraPose& b) {
  return a.orientation.normalized().angularDistance(b.orientation.normalized()) * 180.0 / M_PI;
}

std::vector<TimedPose> pathCorrections(const std::vector<TimedPose>& path,
                                       const std::vector<std::optional<CameraPose>>& sources) {
  if (sources.size() != path.size())
    throw InvalidArgument("pathCorrections: one source pose (or none) per path pose");
  std::vector<TimedPose> out;
  out.reserve(path.size());
  for (size_t i = 0; i < path.size(); ++i)
    if (sources[i] && path[i].pose.isValid() && sources[i]->isValid())
      out.push_back({path[i].stamp, composePoses(path[i].pose, inversePose(*sources[i]))});
  return out;
}

CameraPose correctedPose(const std::vector<TimedPose>& corrections, double stamp,
                         const CameraPose& source) {
  if (corrections.empty()) throw InvalidArgument("correctedPose: no corrections");
  const auto after = std::upper_bound(corrections.begin(), corrections.end(), stamp,
                                      [](double t, const TimedPose& c) { return t < c.stamp; });
  if (after == corrections.begin()) return composePoses(corrections.front().pose, source);
  const TimedPose& before = *(after - 1);
  if (after == corrections.end() || before.stamp == stamp)
    return composePoses(before.pose, source);
  // The two corrected poses blended (not the corrections themselves): independent of where the
  // world frame's origin lies.
  return interpolatePose({0.0, composePoses(before.pose, source)},
                         {after->stamp - before.stamp, composePoses(after->pose, source)},
                         stamp - before.stamp);
}

std::vector<std::pair<ViewId, CameraPose>> matchCorrections(
    const std::vector<CorrectableKeyframe>& keyframes, const std::vector<TimedPose>& corrections,
    const PoseCorrectionConfig& config) {
  std::vector<std::pair<ViewId, CameraPose>> moves;
  if (corrections.empty()) return moves;
  for (size_t i = 0; i < keyframes.size(); ++i) {
    const CorrectableKeyframe& k = keyframes[i];
    const CameraPose corrected = correctedPose(corrections, k.stamp, k.source);
    if (!corrected.isValid()) continue;
    if ((corrected.position - k.pose.position).norm() > config.min_translation ||
        rotationDegrees(corrected, k.pose) > config.min_rotation_deg)
      moves.emplace_back(static_cast<ViewId>(i), corrected);
  }
  return moves;
}

}  // namespace view_selection::core
