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
  if (centres_.empty() || !(radius >= 0.0)) return;
  if (!std::isfinite(radius) || !centre.allFinite()) {  // no bound: everything
    for (size_t id = 0; id < centres_.size(); ++id) out.push_back(static_cast<ViewId>(id));
    return;
  }
  if (cell_ <= 0.0 || radius > kMaxCellsPerRadius * cell_)
    rebuild(std::max(radius / kCellsPerRadius, 1e-9));
  const std::int64_t lo_x = static_cast<std::int64_t>(std::floor((centre.x() - radius) / cell_));
  const std::int64_t hi_x = static_cast<std::int64_t>(std::floor((centre.x() + radius) / cell_));
  const std::int64_t lo_y = static_cast<std::int64_t>(std::floor((centre.y() - radius) / cell_));
  const std::int64_t hi_y = static_cast<std::int64_t>(std::floor((centre.y() + radius) / cell_));
  const std::int64_t lo_z = static_cast<std::int64_t>(std::floor((centre.z() - radius) / cell_));
  const std::int64_t hi_z = static_cast<std::int64_t>(std::floor((centre.z() + radius) / cell_));
  const double r2 = radius * radius;
  for (std::int64_t x = lo_x; x <= hi_x; ++x)
    for (std::int64_t y = lo_y; y <= hi_y; ++y)
      for (std::int64_t z = lo_z; z <= hi_z; ++z) {
        const auto it = cells_.find(key(x, y, z));
        if (it == cells_.end()) continue;
        for (const ViewId id : it->second)
          if ((centres_[static_cast<size_t>(id)] - centre).squaredNorm() <= r2) out.push_back(id);
      }
  std::sort(out.begin(), out.end());
}

void CameraGrid::clear() {
  cell_ = 0.0;
  centres_.clear();
  cells_.clear();
}

}  // namespace view_selection::core
