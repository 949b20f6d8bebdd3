#include "view_selection/core/pose_history.h"

#include <algorithm>

namespace view_selection::core {

void PoseHistory::add(double stamp, const CameraPose& pose) {
  if (!poses_.empty() && !(stamp > poses_.back().stamp)) return;
  TimedPose p{stamp, pose};
  p.pose.orientation.normalize();
  poses_.push_back(p);
  while (poses_.size() > kMaxPoses) poses_.pop_front();
}

std::optional<CameraPose> PoseHistory::at(double stamp, double max_gap) const {
  const auto after = std::lower_bound(poses_.begin(), poses_.end(), stamp,
                                      [](const TimedPose& p, double t) { return p.stamp < t; });
  if (after != poses_.end() && after->stamp == stamp) return after->pose;
  if (after == poses_.begin() || after == poses_.end()) return std::nullopt;
  const TimedPose& before = *(after - 1);
  if (stamp - before.stamp > max_gap || after->stamp - stamp > max_gap) return std::nullopt;
  // Times relative to the earlier pose: at ~1.3e9 s a double resolves only 0.24 us.
  return interpolatePose({0.0, before.pose}, {after->stamp - before.stamp, after->pose},
                         stamp - before.stamp);
}

}  // namespace view_selection::core
