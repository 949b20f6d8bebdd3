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

}  // namespace view_selection
