// The poses the node's pose source gave its frames, by stamp, over a session: what the node had
// at any stamp. A loop-closure path that carries only the SLAM system's own keyframes (VINS'
// pose_graph_path, RTAB-Map's mapPath) corrects the node's keyframes through it: the correction
// at a path pose is that pose composed with the inverse of the one the node had at its stamp.
#pragma once

#include "view_selection/core/pose_interpolation.h"
#include "view_selection/core/types.h"

#include <cstddef>
#include <deque>
#include <optional>
#include <utility>

namespace view_selection::core {

class PoseHistory {
 public:
  /// At most this many poses (about 9 hours of frames at 30 Hz, 64 MB); beyond, the oldest go.
  static constexpr size_t kMaxPoses = 1000000;

  /// Appends a pose (its quaternion normalised); a stamp not after the last one's is ignored (a
  /// session's frames come in increasing stamps; a new session starts with clear()).
  void add(double stamp, const CameraPose& pose);
  /// The pose at `stamp`: the one recorded at that stamp, else the two around it interpolated
  /// when each is within `max_gap` [s] of it; nothing otherwise (never extrapolated).
  std::optional<CameraPose> at(double stamp, double max_gap) const;
  void clear() { poses_.clear(); }
  /// The stamps of the oldest and the newest pose kept, if any.
  std::optional<std::pair<double, double>> span() const {
    if (poses_.empty()) return std::nullopt;
    return std::make_pair(poses_.front().stamp, poses_.back().stamp);
  }
  size_t size() const { return poses_.size(); }
  bool empty() const { return poses_.empty(); }

 private:
  std::deque<TimedPose> poses_;  // ascending stamp
};

}  // namespace view_selection::core
