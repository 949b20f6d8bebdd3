#include "view_selection/core/keyframe_neighbours.h"

#include "view_selection/core/keyframe_policy.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace view_selection::core {

void KeyframeNeighbours::update(ViewId id, const Keyframe& keyframe, double overlap) {
  const size_t index = static_cast<size_t>(id);
  const bool is_new = index >= entries_.size();
  if (is_new) entries_.resize(index + 1);
  Entry& e = entries_[index];
  e.centre = keyframe.pose.position;
  const Eigen::Matrix3d rotation = keyframe.pose.rotation();
  e.axis = rotation.col(2);
  e.focal = std::sqrt(keyframe.intrinsics.fx * keyframe.intrinsics.fy);
  const Eigen::Matrix3Xd& points = keyframe.points;
  const Eigen::Index n = points.cols();
  e.usable = false;
  e.depth = e.reach = 0.0;
  if (n >= kMinReferencePoints && e.focal > 0.0) {
    std::vector<double> values;
    values.reserve(static_cast<size_t>(n));
    for (Eigen::Index q = 0; q < n; ++q) {
      const double z = e.axis.dot(points.col(q) - e.centre);
      if (z > 0.0) values.push_back(z);
    }
    if (!values.empty()) {
      std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2),
                       values.end());
      e.depth = values[values.size() / 2];
      // A covered frame sees at least m of the points within the footprint gate: the m-th
      // farthest bounds how far from the centre it can be (ErrorResistanceMatrix's countedReach).
      values.clear();
      for (Eigen::Index q = 0; q < n; ++q) values.push_back((points.col(q) - e.centre).norm());
      const auto m = static_cast<size_t>(
          std::clamp(std::ceil(overlap * static_cast<double>(n)), 1.0, static_cast<double>(n)));
      std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(m - 1),
                       values.end(), std::greater<double>());
      e.reach = values[m - 1];
      e.usable = e.depth > 0.0;
    }
  }
  if (e.usable) {
    max_reach_ = std::max(max_reach_, e.reach);
    min_focal_ = min_focal_ > 0.0 ? std::min(min_focal_, e.focal) : e.focal;
  }
  if (is_new) {
    grid_.insert(id, e.centre);
  } else {
    grid_.move(id, e.centre);
  }
}

void KeyframeNeighbours::clear() {
  grid_.clear();
  entries_.clear();
  max_reach_ = min_focal_ = 0.0;
}

void KeyframeNeighbours::query(const CameraPose& pose, double focal, double max_scale_ratio,
                               size_t max, std::vector<ViewId>& out, ViewId below) {
  out.clear();
  if (entries_.empty() || !(min_focal_ > 0.0) || max == 0) return;
  const double slack = 1.0 + 1e-9;
  const bool bounded = max_scale_ratio > 0.0;
  const double radius = bounded ? slack * max_reach_ * (1.0 + max_scale_ratio * focal / min_focal_)
                                : std::numeric_limits<double>::infinity();
  grid_.query(pose.position, radius, found_);
  const Eigen::Vector3d axis = pose.rotation().col(2);
  ranked_.clear();
  for (const ViewId id : found_) {
    if (id >= below) continue;
    const Entry& e = entries_[static_cast<size_t>(id)];
    if (!e.usable) continue;
    const double distance = (e.centre - pose.position).norm();
    if (bounded && distance > slack * e.reach * (1.0 + max_scale_ratio * focal / e.focal)) continue;
    const double turned = std::atan2(axis.cross(e.axis).norm(), axis.dot(e.axis));
    ranked_.emplace_back(distance / e.depth + turned, id);
  }
  const size_t keep = std::min(max, ranked_.size());
  std::partial_sort(ranked_.begin(), ranked_.begin() + static_cast<std::ptrdiff_t>(keep),
                    ranked_.end());
  for (size_t q = 0; q < keep; ++q) out.push_back(ranked_[q].second);
}

}  // namespace view_selection::core
