// A points-only sequence for runs at scale: a camera walking down a long straight corridor
// (a SLAM session through a building), one keyframe every `spacing` metres, each with sample
// points ray-cast onto the corridor's walls, floor and ceiling from random pixels. No images
// are rendered. Deterministic from the seed; each keyframe depends only on (seed, index), so any
// part of the walk can be made on its own.
#pragma once

#include "view_selection/core/types.h"
#include "view_selection/io/points_file.h"

#include <cstdint>
#include <functional>
#include <string>

namespace view_selection::sim {

struct CorridorWalkConfig {
  uint64_t seed = 1;
  int frames = 10000;
  core::PinholeIntrinsics intrinsics;  ///< default: 640 x 480, fx = fy = 525
  double spacing = 0.2;                ///< [m] between keyframes along the corridor
  double width = 4.0;                  ///< [m] wall to wall (x)
  double height = 3.0;                 ///< [m] floor to ceiling (y, down)
  double max_range = 25.0;             ///< [m] farthest point seen along a ray
  int points = 256;                    ///< sample points a keyframe
  double start_stamp = 1000.0;         ///< [s] stamp of keyframe 0
  double period = 0.25;                ///< [s] between keyframe stamps

  CorridorWalkConfig();
  /// Throws InvalidArgument naming the bad value.
  void validate() const;
};

/// Keyframe `index` of the walk: stamp, pose (optical frame: z forward, y down) and points.
io::PointsRecord corridorKeyframe(const CorridorWalkConfig& config, int index);

/// Writes `folder`/points.bin, groundtruth.txt, camera.yaml and SOURCE.md (created; existing files
/// of those names are replaced). `progress(done, total)` is called now and then.
void writeCorridorWalk(const std::string& folder, const CorridorWalkConfig& config,
                       const std::function<void(size_t, size_t)>& progress = {});

}  // namespace view_selection::sim
