#include "view_selection/refine/triangulation_c.h"

#include "view_selection/refine/triangulation.h"

#include <cmath>

using view_selection::refine::TrackObservation;
using view_selection::refine::TriangulationRule;

int vs_triangulation_abi(void) { return VS_TRIANGULATION_ABI; }

int vs_triangulate_tracks(int64_t n_tracks, const int64_t* offsets, const double* poses, const double* intrinsics,
                          const double* xy, double max_error_px, double min_angle_deg, int32_t drop_one_by_one,
                          double* points, uint8_t* ok, double* mean_error, uint8_t* inlier) {
  if (n_tracks < 0 || !offsets || offsets[0] != 0 || !(max_error_px > 0.0) || !(min_angle_deg >= 0.0) ||
      drop_one_by_one < 0)
    return -1;
  for (int64_t j = 0; j < n_tracks; ++j)
    if (offsets[j + 1] < offsets[j]) return -1;
  if (n_tracks > 0 && (!poses || !intrinsics || !xy || !points || !ok || !mean_error || !inlier)) return -1;
  const TriangulationRule rule{max_error_px, min_angle_deg, drop_one_by_one};
  std::vector<TrackObservation> track;
  for (int64_t j = 0; j < n_tracks; ++j) {
    track.clear();
    for (int64_t i = offsets[j]; i < offsets[j + 1]; ++i) {
      TrackObservation o;
      const double* p = poses + 12 * i;
      o.R << p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8];
      o.t << p[9], p[10], p[11];
      o.k << intrinsics[4 * i], intrinsics[4 * i + 1], intrinsics[4 * i + 2], intrinsics[4 * i + 3];
      o.xy << xy[2 * i], xy[2 * i + 1];
      track.push_back(o);
      inlier[i] = 0;
    }
    const auto point = view_selection::refine::triangulateTrack(track, rule);
    ok[j] = point.ok ? 1 : 0;
    mean_error[j] = point.mean_error;
    for (int d = 0; d < 3; ++d) points[3 * j + d] = point.x[d];
    if (point.ok)
      for (const int q : point.inliers) inlier[offsets[j] + q] = 1;
  }
  return 0;
}
