#include "view_selection/points/map_point_source.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>

namespace view_selection::points {

void MapPointSourceConfig::visitParameters(core::ParameterVisitor& v) {
  v.section("Points from a map (point_source: map)");
  core::visitReal(v, "map_max_depth", max_depth, 0.0, 1e9,
                  "map: farthest point assigned to a keyframe along its axis; 0 = no limit");
  core::visitInteger(v, "map_max_points", max_points, 0, 100000000,
                     "map: points per keyframe (evenly thinned beyond); 0 = all");
}

Eigen::Matrix3Xd visibleMapPoints(const Eigen::Matrix3Xd& points,
                                  const core::PinholeIntrinsics& intrinsics,
                                  const core::CameraPose& pose, const core::DepthMap* depth,
                                  const MapPointSourceConfig& config) {
  const Eigen::Matrix3d world_to_camera = pose.rotation().transpose();
  std::vector<Eigen::Index> visible;
  for (Eigen::Index c = 0; c < points.cols(); ++c) {
    const Eigen::Vector3d p = world_to_camera * (points.col(c) - pose.position);
    if (!(p.z() > 0.0)) continue;
    if (config.max_depth > 0.0 && p.z() > config.max_depth) continue;
    const Eigen::Vector2d px = intrinsics.project(p);
    if (!intrinsics.inImage(px)) continue;
    if (depth && !depth->empty() && core::occluded(*depth, px.x(), px.y(), p.z(), config.occlusion))
      continue;  // the keyframe saw another surface there
    visible.push_back(c);
  }
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

void MapPointSource::setMapPoints(Eigen::Matrix3Xd points) {
  if (!points.allFinite()) throw core::InvalidInput("map point source: map points must be finite");
  map_ = std::move(points);
  for (View& v : views_) {
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
