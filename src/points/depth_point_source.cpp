#include "view_selection/points/depth_point_source.h"

#include "view_selection/core/exceptions.h"

namespace view_selection::points {

DepthPointSource::DepthPointSource(DepthSamplerConfig config) : config_(config) {
  config_.validate();
}

core::PointSourceResult DepthPointSource::process(core::ViewId /*id*/, const core::Frame& frame) {
  if (frame.depth.empty())
    throw core::InvalidInput("point source 'depth' needs a depth image, but the frame has none");
  core::PointSourceResult result;
  result.points = sampleDepthPoints(frame.depth, frame.intrinsics, frame.pose, config_);
  return result;
}

}  // namespace view_selection::points
