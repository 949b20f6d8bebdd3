#include "view_selection/points/map_point_source.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <unordered_map>

namespace view_selection::points {

void MapPointSourceConfig::visitParameters(core::ParameterVisitor& v) {
  v.section("Points from a map (point_source: map)");
  core::visitReal(v, "map_max_depth", max_depth, 0.0, 1e9,
                  "map: farthest point assigned to a keyframe along its axis; 0 = no limit");
  core::visitInteger(v, "map_max_points", max_points, 0, 100000000,
                     "map: points per keyframe (evenly thinned beyond); 0 = all");
}

namespace {
/// Whether the camera sees `p` (in front, within max_depth, in the image, not occluded).
bool sees(const Eigen::Matrix3d& world_to_camera, const Eigen::Vector3d& position,
          const core::PinholeIntrinsics& intrinsics, const core::DepthMap* depth,
          const MapPointSourceConfig& config, const Eigen::Vector3d& point) {
  const Eigen::Vector3d p = world_to_camera * (point - position);
  if (!(p.z() > 0.0)) return false;
  if (config.max_depth > 0.0 && p.z() > config.max_depth) return false;
  const Eigen::Vector2d px = intrinsics.project(p);
  if (!intrinsics.inImage(px)) return false;
  // Occluded: the keyframe saw another surface there.
  return !(depth && !depth->empty() &&
           core::occluded(*depth, px.x(), px.y(), p.z(), config.occlusion));
}

}  // namespace

Eigen::Matrix3Xd visibleMapPoints(const Eigen::Matrix3Xd& points,
                                  const core::PinholeIntrinsics& intrinsics,
                                  const core::CameraPose& pose, const core::DepthMap* depth,
                                  const MapPointSourceConfig& config) {
  const Eigen::Matrix3d world_to_camera = pose.rotation().transpose();
  std::vector<Eigen::Index> visible;
  for (Eigen::Index c = 0; c < points.cols(); ++c)
    if (sees(world_to_camera, pose.position, intrinsics, depth, config, points.col(c)))
      visible.push_back(c);
  size_t keep = visible.size();
  if (config.max_points > 0) keep = std::min(keep, static_cast<size_t>(config.max_points));
  Eigen::Matrix3Xd out(3, static_cast<Eigen::Index>(keep));
  for (size_t q = 0; q < keep; ++q) {
    // Evenly spread over the visible ones: index floor(q * visible / keep).
    const size_t k = q * visible.size() / keep;
    out.col(static_cast<Eigen::Index>(q)) = points.col(visible[k]);
  }
  return out;
}

MapPointSource::MapPointSource(MapPointSourceConfig config) : config_(config) {
  config_.validate();
}

void MapPointSource::reset() {
  map_.resize(3, 0);
  views_.clear();
}

namespace {

/// A point's exact coordinates, for matching the points of two maps.
struct PointKey {
  std::uint64_t x, y, z;
  bool operator==(const PointKey& o) const { return x == o.x && y == o.y && z == o.z; }
};
struct PointKeyHash {
  size_t operator()(const PointKey& k) const {
    std::uint64_t h = k.x * 0x9e3779b97f4a7c15ULL;
    h ^= k.y + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2);
    h ^= k.z + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2);
    return static_cast<size_t>(h);
  }
};
PointKey keyOf(const Eigen::Vector3d& p) {
  PointKey k;
  std::memcpy(&k.x, &p.x(), sizeof k.x);
  std::memcpy(&k.y, &p.y(), sizeof k.y);
  std::memcpy(&k.z, &p.z(), sizeof k.z);
  return k;
}

}  // namespace

std::optional<Eigen::Matrix3Xd> changedMapPoints(const Eigen::Matrix3Xd& before,
                                                 const Eigen::Matrix3Xd& after) {
  // Each point of `before` by its exact coordinates (repeated points: each occurrence once).
  std::unordered_map<PointKey, std::vector<Eigen::Index>, PointKeyHash> old;
  old.reserve(static_cast<size_t>(before.cols()));
  for (Eigen::Index c = before.cols(); c-- > 0;) old[keyOf(before.col(c))].push_back(c);
  std::vector<Eigen::Index> changed;  // columns of `after` that are new, then of `before` gone
  std::vector<char> kept(static_cast<size_t>(before.cols()), 0);
  Eigen::Index last = -1;
  for (Eigen::Index c = 0; c < after.cols(); ++c) {
    auto it = old.find(keyOf(after.col(c)));
    if (it == old.end() || it->second.empty()) {
      changed.push_back(c);
      continue;
    }
    const Eigen::Index was = it->second.back();  // the earliest unmatched occurrence
    it->second.pop_back();
    if (was < last) return std::nullopt;  // kept points in another order
    last = was;
    kept[static_cast<size_t>(was)] = 1;
  }
  Eigen::Matrix3Xd out(3, static_cast<Eigen::Index>(changed.size()));
  for (size_t q = 0; q < changed.size(); ++q) out.col(static_cast<Eigen::Index>(q)) = after.col(changed[q]);
  std::vector<Eigen::Index> gone;
  for (Eigen::Index c = 0; c < before.cols(); ++c)
    if (!kept[static_cast<size_t>(c)]) gone.push_back(c);
  const Eigen::Index added = out.cols();
  out.conservativeResize(3, added + static_cast<Eigen::Index>(gone.size()));
  for (size_t q = 0; q < gone.size(); ++q)
    out.col(added + static_cast<Eigen::Index>(q)) = before.col(gone[q]);
  return out;
}

void MapPointSource::setMapPoints(Eigen::Matrix3Xd points) {
  if (!points.allFinite()) throw core::InvalidInput("map point source: map points must be finite");
  // A keyframe that sees none of the points that came or went, while the points that stayed
  // kept their order, has the same assignment: only the others are projected against the map.
  const std::optional<Eigen::Matrix3Xd> changed =
      views_.empty() ? std::nullopt : changedMapPoints(map_, points);
  map_ = std::move(points);
  reassigned_ = 0;
  for (View& v : views_) {
    if (changed) {
      const Eigen::Matrix3d world_to_camera = v.pose.rotation().transpose();
      bool affected = false;
      for (Eigen::Index c = 0; c < changed->cols() && !affected; ++c)
        affected = sees(world_to_camera, v.pose.position, v.intrinsics, v.depth.get(), config_,
                        changed->col(c));
      if (!affected) continue;
    }
    ++reassigned_;
    Eigen::Matrix3Xd assigned =
        visibleMapPoints(map_, v.intrinsics, v.pose, v.depth.get(), config_);
    if (assigned.cols() == v.assigned.cols() && assigned == v.assigned) continue;
    v.assigned = std::move(assigned);
    v.pending = true;
  }
}

void MapPointSource::restore(State state) {
  if (!state.map.allFinite()) throw core::InvalidInput("map point source: map points not finite");
  for (size_t i = 0; i < state.views.size(); ++i) {
    const View& v = state.views[i];
    if (v.id < 0 || (i > 0 && v.id <= state.views[i - 1].id))
      throw core::InvalidInput("map point source: keyframe ids do not ascend");
    if (!v.intrinsics.isValid() || !v.pose.isValid() || !v.assigned.allFinite())
      throw core::InvalidInput("map point source: keyframe " + std::to_string(v.id) +
                               " has invalid intrinsics, pose or points");
    if (v.depth && !v.depth->isConsistent())
      throw core::InvalidInput("map point source: keyframe " + std::to_string(v.id) +
                               " has an inconsistent depth map");
  }
  map_ = std::move(state.map);
  views_ = std::move(state.views);
}

std::vector<core::ViewId> MapPointSource::pendingUpdates() const {
  std::vector<core::ViewId> ids;
  for (const View& v : views_)
    if (v.pending) ids.push_back(v.id);
  return ids;
}

std::vector<std::pair<core::ViewId, Eigen::Matrix3Xd>> MapPointSource::takeUpdates() {
  std::vector<std::pair<core::ViewId, Eigen::Matrix3Xd>> updates;
  for (View& v : views_) {
    if (!v.pending) continue;
    updates.emplace_back(v.id, v.assigned);
    v.pending = false;
  }
  return updates;
}

core::PointSourceResult MapPointSource::process(core::ViewId id, const core::Frame& frame) {
  if (!frame.intrinsics.isValid() || !frame.pose.isValid())
    throw core::InvalidInput("map point source: the frame's intrinsics or pose are unusable");
  if (!views_.empty() && id <= views_.back().id)
    throw core::InvalidArgument("map point source: keyframe id " + std::to_string(id) +
                                " is not after the previous one (" +
                                std::to_string(views_.back().id) + "); call reset() to start over");
  View v;
  v.id = id;
  v.intrinsics = frame.intrinsics;
  v.pose = frame.pose;
  if (config_.occlusion.enabled && !frame.depth.empty())
    v.depth = std::make_shared<const core::DepthMap>(
        core::makeOcclusionMap(frame.depth, frame.intrinsics, config_.occlusion.depth_map_cell));
  v.assigned = visibleMapPoints(map_, v.intrinsics, v.pose, v.depth.get(), config_);
  core::PointSourceResult result;
  result.updated = takeUpdates();
  result.points = v.assigned;
  views_.push_back(std::move(v));
  return result;
}

}  // namespace view_selection::points
