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
  /// ascending. Chooses its cell size from the first query; regrids coarser after kCoarserAfter
  /// queries in a row outgrow it, and finer again after kFinerAfter queries in a row far smaller than it. A query
  /// that would look up more cells than there are centres compares every centre instead.
  void query(const Eigen::Vector3d& centre, double radius, std::vector<ViewId>& out);
  /// The cell size now (0: none chosen yet); for tests.
  double cellSize() const { return cell_; }
  /// Centres compared with the radius by the last query (for tests and benchmarks).
  size_t lastExamined() const { return examined_; }
  void clear();
  size_t size() const { return centres_.size(); }

 private:
  static constexpr double kCellsPerRadius = 2.0;    ///< cell = radius / 2 at the first query
  static constexpr double kMaxCellsPerRadius = 8;  ///< beyond, the grid is rebuilt coarser
  static constexpr int kFinerAfter = 32;  ///< queries under cell / (2 * 8) in a row: finer
  static constexpr int kCoarserAfter = 4;  ///< queries over 8 cells in a row: coarser
  using Key = std::int64_t;
  Key key(const Eigen::Vector3d& p) const;
  Key key(std::int64_t x, std::int64_t y, std::int64_t z) const;
  void rebuild(double cell);

  double cell_ = 0.0;  // 0: not chosen yet
  int small_queries_ = 0;     // in a row, far smaller than the cells
  double small_radius_ = 0.0;  // the largest of them
  int large_queries_ = 0;      // in a row, outgrowing the cells
  double large_radius_ = 0.0;  // the smallest of them
  size_t examined_ = 0;
  std::vector<Eigen::Vector3d> centres_;  // by id
  std::unordered_map<Key, std::vector<ViewId>> cells_;
};

}  // namespace view_selection::core
