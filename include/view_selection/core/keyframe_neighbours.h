// The keyframes near a frame that may already cover its view, for the scale_free policy's
// revisit rule: walking round a place again adds no keyframe where an earlier keyframe already
// has the view (ViewSelector). Camera centres in a CameraGrid, and per keyframe what bounds and
// ranks the search: angles and ratios only, like the rule itself.
#pragma once

#include "view_selection/core/camera_grid.h"
#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <cstddef>
#include <limits>
#include <utility>
#include <vector>

namespace view_selection::core {

class KeyframeNeighbours {
 public:
  /// Keyframe `id` is `keyframe` now: a new one (the next id) or one whose points or pose
  /// changed. `overlap`: the share of its points a frame it covers must see (keyframe_overlap).
  void update(ViewId id, const Keyframe& keyframe, double overlap);
  void clear();
  size_t size() const { return entries_.size(); }

  /// Up to `max` keyframes that can cover the view of a frame at `pose` (focal length `focal` =
  /// sqrt(fx fy)), the most alike first, into `out`. A keyframe can cover it only when at least
  /// `overlap` of its points pass the footprint-ratio gate `max_scale_ratio` (0: off, no bound)
  /// in the frame, so its centre lies within (1 + ratio f / f_k) of the distance of the
  /// `overlap`-th share of its points (the bound is exact: none that can is left out for it).
  /// Alike: the distance between the centres over the keyframe's median depth plus the angle
  /// between the optical axes [rad] (a sideways step of 1/10 of the depth is worth a turn of
  /// 0.1 rad: both move the image by about a tenth of a focal length).
  /// Only keyframes with an id below `below` are looked at (default: all).
  void query(const CameraPose& pose, double focal, double max_scale_ratio, size_t max,
             std::vector<ViewId>& out, ViewId below = std::numeric_limits<ViewId>::max());

 private:
  struct Entry {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  ///< optical axis, world
    double depth = 0.0;  ///< median depth of its points in front
    double reach = 0.0;  ///< the distance from the centre of its `overlap`-th share of points
    double focal = 0.0;
    bool usable = false;  ///< enough points to measure against (kMinReferencePoints)
  };
  CameraGrid grid_;
  std::vector<Entry> entries_;  // by id
  // Bounds of the grid's search: they only grow (max) and shrink (min) between clear()s, so a
  // search is at worst wider than needed, never narrower.
  double max_reach_ = 0.0;
  double min_focal_ = 0.0;
  std::vector<ViewId> found_;                     // reused
  std::vector<std::pair<double, ViewId>> ranked_;  // reused
};

}  // namespace view_selection::core
