// Tracks of a project's verified matches, for re-triangulating a model at refined poses: every
// match joins two observations (image, 2D point index) into one track (union-find), unless that
// would give a track two observations of one image (the match is left out, as COLMAP's track
// building and the live model do).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace view_selection::refine {

struct Observation {
  int image_id = 0;
  int point2D_idx = 0;
  bool operator==(const Observation& o) const { return image_id == o.image_id && point2D_idx == o.point2D_idx; }
};

struct Match {
  Observation a, b;
};

struct Tracks {
  std::vector<std::vector<Observation>> tracks;  ///< each with at least two observations
  size_t conflicts = 0;                          ///< matches left out
};

Tracks buildTracks(const std::vector<Match>& matches);

/// How many distinct observations (image, 2D point index >= 0) the matches hold: what their
/// tracks hold but the observations of the matches left out for a conflict, in a fraction of
/// buildTracks' time (what refine_model weighs a triangulation's cost by before building them).
size_t countObservations(const std::vector<Match>& matches);

/// A matches file: "VSMATCH1", a little-endian uint64 count, then count x 4 int32 (image id,
/// 2D point index, image id, 2D point index). Throws core::IoError naming the file.
std::vector<Match> readMatches(const std::string& path);
void writeMatches(const std::string& path, const std::vector<Match>& matches);

}  // namespace view_selection::refine
