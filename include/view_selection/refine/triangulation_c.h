// The triangulation (triangulation.h) behind a C interface, for colmap_bridge's live model in
// Python (ctypes; live/triangulation.py), in the shared library libview_selection_triangulation:
// one call triangulates a whole update's tracks, so the live model and the refinement keep and
// drop points by the same code.
#pragma once

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Bumped when a signature below changes; the Python side checks it.
#define VS_TRIANGULATION_ABI 1
int vs_triangulation_abi(void);

/// Triangulates `n_tracks` tracks. Track j's observations are those with indices offsets[j] to
/// offsets[j + 1] - 1 (offsets has n_tracks + 1 entries, ascending, offsets[0] = 0). Observation i
/// has its camera's pose poses[12 i ...] (R row-major, then t; world to camera), intrinsics
/// intrinsics[4 i ...] (fx, fy, cx, cy) and its pixel xy[2 i ...].
/// Writes points[3 j ...], ok[j] (1: kept), mean_error[j] [px] and inlier[i] (1: kept in its
/// point). Returns 0, or -1 for an argument that is not valid (nothing written then).
int vs_triangulate_tracks(int64_t n_tracks, const int64_t* offsets, const double* poses, const double* intrinsics,
                          const double* xy, double max_error_px, double min_angle_deg, int32_t drop_one_by_one,
                          double* points, uint8_t* ok, double* mean_error, uint8_t* inlier);

#ifdef __cplusplus
}
#endif
