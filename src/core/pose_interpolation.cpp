#include "view_selection/core/pose_interpolation.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>

namespace view_selection::core {

CameraPose interpolatePose(const TimedPose& a, const TimedPose& b, double stamp) {
  const double span = b.stamp - a.stamp;
  const Eigen::Quaterniond qa = a.pose.orientation.normalized();
  if (span == 0.0) {
    CameraPose out = a.pose;
    out.orientation = qa;
    return out;
  }
  const double s = (stamp - a.stamp) / span;
  CameraPose out;
  out.position = a.pose.position + s * (b.pose.position - a.pose.position);
  // Eigen's slerp takes the shorter arc (it flips b when the dot product is negative).
  out.orientation = qa.slerp(s, b.pose.orientation.normalized()).normalized();
  return out;
}

CameraPose composePoses(const CameraPose& a, const CameraPose& b) {
  CameraPose out;
  const Eigen::Quaterniond qa = a.orientation.normalized();
  out.position = a.position + qa * b.position;
  out.orientation = (qa * b.orientation.normalized()).normalized();
  return out;
}

CameraPose inversePose(const CameraPose& a) {
  CameraPose out;
  out.orientation = a.orientation.normalized().conjugate();
  out.position = -(out.orientation * a.position);
  return out;
}

CameraPose poseOnTrajectory(const std::vector<TimedPose>& trajectory, double stamp) {
  if (trajectory.empty()) throw InvalidArgument("poseOnTrajectory: the trajectory is empty");
  const auto after = std::upper_bound(trajectory.begin(), trajectory.end(), stamp,
                                      [](double t, const TimedPose& p) { return t < p.stamp; });
  if (after == trajectory.begin())
    return interpolatePose(trajectory.front(), trajectory.front(), stamp);
  if (after == trajectory.end())
    return interpolatePose(trajectory.back(), trajectory.back(), stamp);
  return interpolatePose(*(after - 1), *after, stamp);
}

}  // namespace view_selection::core
