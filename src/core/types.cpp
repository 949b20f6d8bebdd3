#include "view_selection/core/types.h"

#include <cmath>

namespace view_selection::core {

bool PinholeIntrinsics::isValid() const {
  return std::isfinite(fx) && std::isfinite(fy) && std::isfinite(cx) && std::isfinite(cy) &&
         fx > 0.0 && fy > 0.0 && width > 0 && height > 0;
}

Eigen::Matrix3d PinholeIntrinsics::matrix() const {
  Eigen::Matrix3d k;
  k << fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
  return k;
}

bool CameraPose::isValid() const {
  if (!position.allFinite() || !orientation.coeffs().allFinite()) return false;
  // A quaternion far from unit length is a symptom of a bad message (e.g. all zeros), not
  // rounding; small deviations (7-digit TUM files) are normalised when used.
  return std::abs(orientation.norm() - 1.0) <= 0.05;
}

bool DepthMap::isConsistent() const {
  if (cols < 0 || rows < 0 || !(cell_width > 0.0) || !(cell_height > 0.0) ||
      !std::isfinite(cell_width) || !std::isfinite(cell_height) ||
      depth.size() != static_cast<size_t>(cols) * static_cast<size_t>(rows))
    return false;
  for (const float d : depth)
    if (!std::isfinite(d) || d < 0.0f) return false;
  return true;
}

}  // namespace view_selection::core
