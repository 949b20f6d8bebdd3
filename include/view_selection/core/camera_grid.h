// A spatial hash of keyframe camera centres, so that inserting a keyframe looks only at the
// keyframes near enough to share a matchable point with it, not at all of them.
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <cstdint>
#include <unordered_map>
#include <vector>

namespace view_selection::core {

class CameraGrid {
 public:
  void insert(ViewId id, const Eigen::Vector3d& centre);
  /// Moves the centre of `id` (inserted before) to `centre` (a loop closure corrected it).
  void move(ViewId id, const Eigen::Vector3d& centre);
  /// Ids of the centres within `radius` of `centre` (a superset test on cells, then exact),
  /// ascending. Chooses its cell size from the first query; regrids when queries outgrow it.
  void query(const Eigen::Vector3d& centre, double radius, std::vector<ViewId>& out);
  void clear();
  size_t size() const { return centres_.size(); }

 private:
  static constexpr double kCellsPerRadius = 2.0;    ///< cell = radius / 2 at the first query
  static constexpr double kMaxCellsPerRadius = 8;  ///< beyond, the grid is rebuilt coarser
  using Key = std::int64_t;
  Key key(const Eigen::Vector3d& p) const;
  Key key(std::int64_t x, std::int64_t y, std::int64_t z) const;
  void rebuild(double cell);

  double cell_ = 0.0;  // 0: not chosen yet
  std::vector<Eigen::Vector3d> centres_;  // by id
  std::unordered_map<Key, std::vector<ViewId>> cells_;
};

}  // namespace view_selection::core
