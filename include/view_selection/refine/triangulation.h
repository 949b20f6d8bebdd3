// A 3D point from a track of observations at known poses: the one triangulation of the package,
// used by the refinement's re-triangulation (model_refinement.cpp) and, through its C interface
// (triangulation_c.h), by colmap_bridge's live model (live/model.py), so that a point is kept or
// dropped by the same rules wherever it is made (issue 34: "one triangulation").
//
// The rules: a linear (DLT) point from the normalised rays, three Gauss-Newton steps on the pixel
// error with the poses held, then, while an observation lies further than max_error_px from the
// point's projection or behind its camera, observations are dropped and the point made again from
// the rest: the worst alone for drop_one_by_one rounds, then every one beyond the limit at once (a
// long track is not triangulated once per bad observation). The point is kept with at least two
// observations left, all in front of their cameras, and a triangulation angle (the widest pair of
// rays) of at least min_angle_deg.
#pragma once

#include <Eigen/Core>

#include <vector>

namespace view_selection::refine {

struct TriangulationRule {
  /// [px] the furthest an observation may lie from the point's projection (tighter than COLMAP's
  /// 4 px filter: measured on the kitchen, 3 px keeps 5,934 points at 1.34 px mean error where
  /// 4 px keeps 6,431 at 1.73 px; docs/live.md).
  double max_error_px = 3.0;
  /// [deg] COLMAP 3.8's point_triangulator default (tri_min_angle).
  double min_angle_deg = 1.5;
  /// Rounds in which only the worst observation is dropped before every one beyond the limit
  /// goes at once (measured on the kitchen and a 3-minute walk: one by one throughout kept 5,497
  /// points and cost 21.7 s of CPU on the walk; 6 rounds 5,474 and 21.3 s; 3 rounds 5,347).
  int drop_one_by_one = 6;
};

/// One observation: the camera's pose (world to camera: x_cam = R x + t), its pinhole
/// intrinsics (fx, fy, cx, cy, in the same pixel convention as xy) and the observed pixel.
struct TrackObservation {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  Eigen::Vector4d k;
  Eigen::Vector2d xy;
};

struct TriangulatedPoint {
  bool ok = false;
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  std::vector<int> inliers;  ///< indices of the observations kept, ascending
  double mean_error = 0.0;   ///< [px] over the inliers
};

/// The point of one track, under `rule`.
TriangulatedPoint triangulateTrack(const std::vector<TrackObservation>& track, const TriangulationRule& rule = {});

/// [px] the reprojection error of `x` in an observation, and its depth in that camera.
std::pair<double, double> reprojectionError(const TrackObservation& o, const Eigen::Vector3d& x);

}  // namespace view_selection::refine
