#include "view_selection/core/camera_grid.h"

#include <algorithm>
#include <cmath>

namespace view_selection::core {

namespace {
constexpr std::int64_t kBits = 21;  // per axis: 2^21 cells each way
constexpr std::int64_t kMask = (std::int64_t{1} << kBits) - 1;
}  // namespace

CameraGrid::Key CameraGrid::key(std::int64_t x, std::int64_t y, std::int64_t z) const {
  return ((x & kMask) << (2 * kBits)) | ((y & kMask) << kBits) | (z & kMask);
}

CameraGrid::Key CameraGrid::key(const Eigen::Vector3d& p) const {
  return key(static_cast<std::int64_t>(std::floor(p.x() / cell_)),
             static_cast<std::int64_t>(std::floor(p.y() / cell_)),
             static_cast<std::int64_t>(std::floor(p.z() / cell_)));
}

void CameraGrid::insert(ViewId id, const Eigen::Vector3d& centre) {
  if (static_cast<size_t>(id) >= centres_.size()) centres_.resize(static_cast<size_t>(id) + 1);
  centres_[static_cast<size_t>(id)] = centre;
  if (cell_ > 0.0) cells_[key(centre)].push_back(id);
}

void CameraGrid::move(ViewId id, const Eigen::Vector3d& centre) {
  Eigen::Vector3d& old = centres_.at(static_cast<size_t>(id));
  if (cell_ > 0.0) {
    const Key from = key(old), to = key(centre);
    if (from != to) {
      const auto it = cells_.find(from);
      if (it != cells_.end()) {
        it->second.erase(std::remove(it->second.begin(), it->second.end(), id), it->second.end());
        if (it->second.empty()) cells_.erase(it);
      }
      cells_[to].push_back(id);
    }
  }
  old = centre;
}

void CameraGrid::rebuild(double cell) {
  cell_ = cell;
  cells_.clear();
  for (size_t id = 0; id < centres_.size(); ++id) cells_[key(centres_[id])].push_back(static_cast<ViewId>(id));
}

void CameraGrid::query(const Eigen::Vector3d& centre, double radius, std::vector<ViewId>& out) {
  out.clear();
  examined_ = 0;
  if (centres_.empty() || !(radius >= 0.0)) return;
  if (!std::isfinite(radius) || !centre.allFinite()) {  // no bound: everything
    for (size_t id = 0; id < centres_.size(); ++id) out.push_back(static_cast<ViewId>(id));
    examined_ = centres_.size();
    return;
  }
  if (cell_ <= 0.0) {
    rebuild(std::max(radius / kCellsPerRadius, 1e-9));
  } else if (radius > kMaxCellsPerRadius * cell_) {
    // Outgrown: one such query (an outlier's) is answered as it is; a run of them regrids.
    large_radius_ = large_queries_ == 0 ? radius : std::min(large_radius_, radius);
    small_queries_ = 0;
    if (++large_queries_ >= kCoarserAfter) {
      rebuild(std::max(large_radius_ / kCellsPerRadius, 1e-9));
      large_queries_ = 0;
    }
  } else if (radius * kCellsPerRadius * kMaxCellsPerRadius < cell_) {
    // Far smaller than the cells (the large reach that made them is gone): after a run of
    // such queries, cells fit for the largest of them.
    small_radius_ = small_queries_ == 0 ? radius : std::max(small_radius_, radius);
    large_queries_ = 0;
    if (++small_queries_ >= kFinerAfter) {
      rebuild(std::max(small_radius_ / kCellsPerRadius, 1e-9));
      small_queries_ = 0;
    }
  } else {
    small_queries_ = large_queries_ = 0;
  }
  const double r2 = radius * radius;
  const auto take = [&](const std::vector<ViewId>& ids) {
    for (const ViewId id : ids) {
      ++examined_;
      if ((centres_[static_cast<size_t>(id)] - centre).squaredNorm() <= r2) out.push_back(id);
    }
  };
  const double span = std::floor(2.0 * radius / cell_) + 2.0;  // cells a side, at most
  if (span * span * span > static_cast<double>(centres_.size())) {
    // More cells to look up than centres to compare: compare them all (an outlier's query).
    for (const auto& [key, ids] : cells_) take(ids);
    std::sort(out.begin(), out.end());
    return;
  }
  const std::int64_t lo_x = static_cast<std::int64_t>(std::floor((centre.x() - radius) / cell_));
  const std::int64_t hi_x = static_cast<std::int64_t>(std::floor((centre.x() + radius) / cell_));
  const std::int64_t lo_y = static_cast<std::int64_t>(std::floor((centre.y() - radius) / cell_));
  const std::int64_t hi_y = static_cast<std::int64_t>(std::floor((centre.y() + radius) / cell_));
  const std::int64_t lo_z = static_cast<std::int64_t>(std::floor((centre.z() - radius) / cell_));
  const std::int64_t hi_z = static_cast<std::int64_t>(std::floor((centre.z() + radius) / cell_));
  for (std::int64_t x = lo_x; x <= hi_x; ++x)
    for (std::int64_t y = lo_y; y <= hi_y; ++y)
      for (std::int64_t z = lo_z; z <= hi_z; ++z) {
        const auto it = cells_.find(key(x, y, z));
        if (it != cells_.end()) take(it->second);
      }
  std::sort(out.begin(), out.end());
}

void CameraGrid::clear() {
  cell_ = 0.0;
  small_queries_ = large_queries_ = 0;
  centres_.clear();
  cells_.clear();
}

}  // namespace view_selection::core
