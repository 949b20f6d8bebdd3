#include "view_selection/core/map_point_source.h"

#include "view_selection/core/depth_sampler.h"
#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>

namespace view_selection {

void MapPointSourceConfig::validate() const {
  auto fail = [](const std::string& what) { throw InvalidArgument("map point source: " + what); };
  if (std::isnan(max_depth) || std::isinf(max_depth))
    fail("max_depth must be finite (<= 0 disables it)");
  if (max_points < 0) fail("max_points must be >= 0 (0: no limit)");
  if (!(occlusion_abs_tolerance >= 0.0) || !std::isfinite(occlusion_abs_tolerance))
    fail("occlusion_abs_tolerance must be >= 0");
  if (!(occlusion_rel_tolerance >= 0.0) || !std::isfinite(occlusion_rel_tolerance))
    fail("occlusion_rel_tolerance must be >= 0");
  if (depth_map_cell < 1) fail("depth_map_cell must be >= 1");
}

nlohmann::json MapPointSourceConfig::toJson() const {
  return {{"max_depth", max_depth},
          {"max_points", max_points},
          {"occlusion_test", occlusion_test},
          {"occlusion_abs_tolerance", occlusion_abs_tolerance},
          {"occlusion_rel_tolerance", occlusion_rel_tolerance},
          {"depth_map_cell", depth_map_cell}};
}

Eigen::Matrix3Xd visibleMapPoints(const Eigen::Matrix3Xd& points,
                                  const PinholeIntrinsics& intrinsics, const CameraPose& pose,
                                  const DepthMap* depth, const MapPointSourceConfig& config) {
  const Eigen::Matrix3d world_to_camera = pose.rotation().transpose();
  std::vector<Eigen::Index> visible;
  for (Eigen::Index c = 0; c < points.cols(); ++c) {
    const Eigen::Vector3d p = world_to_camera * (points.col(c) - pose.position);
    if (!(p.z() > 0.0)) continue;
    if (config.max_depth > 0.0 && p.z() > config.max_depth) continue;
    const Eigen::Vector2d px = intrinsics.project(p);
    if (!intrinsics.inImage(px)) continue;
    if (depth && !depth->empty()) {
      const double d = depth->at(px.x(), px.y());
      if (d > 0.0 && std::abs(p.z() - d) > std::max(config.occlusion_abs_tolerance,
                                                    config.occlusion_rel_tolerance * p.z()))
        continue;  // the keyframe saw another surface there
    }
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
  if (!points.allFinite()) throw InvalidInput("map point source: map points must be finite");
  map_ = std::move(points);
  for (View& v : views_) {
    Eigen::Matrix3Xd assigned =
        visibleMapPoints(map_, v.intrinsics, v.pose, v.depth.get(), config_);
    if (assigned.cols() == v.assigned.cols() && assigned == v.assigned) continue;
    v.assigned = std::move(assigned);
    v.pending = true;
  }
}

std::vector<ViewId> MapPointSource::pendingUpdates() const {
  std::vector<ViewId> ids;
  for (const View& v : views_)
    if (v.pending) ids.push_back(v.id);
  return ids;
}

std::vector<std::pair<ViewId, Eigen::Matrix3Xd>> MapPointSource::takeUpdates() {
  std::vector<std::pair<ViewId, Eigen::Matrix3Xd>> updates;
  for (View& v : views_) {
    if (!v.pending) continue;
    updates.emplace_back(v.id, v.assigned);
    v.pending = false;
  }
  return updates;
}

PointSourceResult MapPointSource::process(ViewId id, const Frame& frame) {
  if (!frame.intrinsics.isValid() || !frame.pose.isValid())
    throw InvalidInput("map point source: the frame's intrinsics or pose are unusable");
  if (!views_.empty() && id <= views_.back().id)
    throw InvalidArgument("map point source: keyframe id " + std::to_string(id) +
                          " is not after the previous one (" + std::to_string(views_.back().id) +
                          "); call reset() to start over");
  if (!frame.depth_m.empty() && frame.depth_m.type() != CV_32FC1)
    throw InvalidInput("map point source: depth must be CV_32FC1 metres");
  View v;
  v.id = id;
  v.intrinsics = frame.intrinsics;
  v.pose = frame.pose;
  if (config_.occlusion_test && !frame.depth_m.empty())
    v.depth = std::make_shared<const DepthMap>(
        downsampleDepth(frame.depth_m, frame.intrinsics, config_.depth_map_cell));
  v.assigned = visibleMapPoints(map_, v.intrinsics, v.pose, v.depth.get(), config_);
  PointSourceResult result;
  result.updated = takeUpdates();
  result.points = v.assigned;
  views_.push_back(std::move(v));
  return result;
}

}  // namespace view_selection
