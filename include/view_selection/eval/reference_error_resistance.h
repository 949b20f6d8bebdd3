// The reference that the closed-form r() of core/error_resistance.h is tested and benchmarked
// against: brute-force re-triangulation with OpenCV. Slow; not for the matrix.
#pragma once

#include "view_selection/core/types.h"

namespace view_selection::eval {

/// The same quantity by brute force: project P into i, move its projection in j by one pixel
/// along the epipolar line each way, re-triangulate with cv::triangulatePoints (DLT) and take the
/// larger displacement. Slow; the reference the closed form is tested and benchmarked against.
double pointErrorResistanceByTriangulation(const Eigen::Vector3d& point,
                                           const core::PinholeIntrinsics& intrinsics_i,
                                           const core::CameraPose& pose_i,
                                           const core::PinholeIntrinsics& intrinsics_j,
                                           const core::CameraPose& pose_j);

}  // namespace view_selection::eval
