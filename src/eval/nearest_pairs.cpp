#include "view_selection/eval/nearest_pairs.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/selection.h"

#include <algorithm>
#include <cmath>
#include <tuple>

namespace view_selection::eval {

void NearestPairsConfig::validate() const {
  if (k < 1)
    throw core::InvalidArgument("nearest pairs: k must be at least 1, got " + std::to_string(k));
  if (!(max_view_angle_deg >= 0.0 && max_view_angle_deg <= 180.0))
    throw core::InvalidArgument("nearest pairs: max_view_angle_deg must be in [0, 180], got " +
                                std::to_string(max_view_angle_deg));
}

std::vector<std::vector<core::ViewId>> nearestNeighbourSets(
    const std::vector<core::CameraPose>& poses, const NearestPairsConfig& config) {
  config.validate();
  const size_t n = poses.size();
  std::vector<Eigen::Vector3d> axes(n);
  for (size_t i = 0; i < n; ++i) {
    if (!poses[i].isValid())
      throw core::InvalidArgument("nearest pairs: pose of view " + std::to_string(i) +
                                  " is invalid");
    axes[i] = poses[i].opticalAxis().normalized();
  }
  // Compare cosines; a small slack so that an angle exactly at the limit counts as inside.
  const double min_cos = std::cos(config.max_view_angle_deg * M_PI / 180.0) - 1e-12;
  std::vector<std::vector<core::ViewId>> sets(n);
  std::vector<std::pair<double, core::ViewId>> candidates;
  for (size_t i = 0; i < n; ++i) {
    candidates.clear();
    for (size_t j = 0; j < n; ++j) {
      if (j == i || axes[i].dot(axes[j]) < min_cos) continue;
      candidates.emplace_back((poses[i].position - poses[j].position).squaredNorm(),
                              static_cast<core::ViewId>(j));
    }
    const size_t take = std::min(candidates.size(), static_cast<size_t>(config.k));
    std::partial_sort(candidates.begin(), candidates.begin() + static_cast<std::ptrdiff_t>(take),
                      candidates.end());
    for (size_t q = 0; q < take; ++q) sets[i].push_back(candidates[q].second);
  }
  return sets;
}

std::vector<std::pair<core::ViewId, core::ViewId>> nearestPairs(
    const std::vector<core::CameraPose>& poses, const NearestPairsConfig& config) {
  return core::pairsFromSets(nearestNeighbourSets(poses, config));
}

}  // namespace view_selection::eval
