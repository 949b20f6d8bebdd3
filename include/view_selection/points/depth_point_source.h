// Points back-projected from the frame's depth image: one robust point per grid cell.
#pragma once

#include "view_selection/core/point_source.h"
#include "view_selection/points/depth_sampler.h"

namespace view_selection::points {

class DepthPointSource : public core::PointSource {
 public:
  explicit DepthPointSource(DepthSamplerConfig config = {});
  std::string name() const override { return "depth"; }
  /// Throws InvalidInput when the frame has no depth.
  core::PointSourceResult process(core::ViewId id, const core::Frame& frame) override;
  void reset() override {}
  core::Params params() const override { return core::paramsOf(config_); }

 private:
  DepthSamplerConfig config_;
};

}  // namespace view_selection::points
