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

}  // namespace view_selection::core
