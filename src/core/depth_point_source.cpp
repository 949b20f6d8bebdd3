#include "view_selection/core/exceptions.h"
#include "view_selection/core/point_source.h"

namespace view_selection {

DepthPointSource::DepthPointSource(DepthSamplerConfig config) : config_(config) {
  config_.validate();
}

PointSourceResult DepthPointSource::process(ViewId /*id*/, const Frame& frame) {
  if (frame.depth_m.empty())
    throw InvalidInput("point source 'depth' needs a depth image, but the frame has none");
  PointSourceResult result;
  result.points = sampleDepthPoints(frame.depth_m, frame.intrinsics, frame.pose, config_);
  return result;
}

nlohmann::json DepthPointSource::params() const {
  return {{"grid_cols", config_.grid_cols},         {"grid_rows", config_.grid_rows},
          {"min_depth", config_.min_depth},         {"max_depth", config_.max_depth},
          {"min_valid_fraction", config_.min_valid_fraction},
          {"pixel_stride", config_.pixel_stride},   {"depth_map_cell", config_.depth_map_cell}};
}

}  // namespace view_selection
