#include "view_selection/core/point_source_factory.h"

#include "view_selection/core/exceptions.h"

namespace view_selection {

void PointSourceParams::validate() const {
  depth.validate();
  features.validate();
  map.validate();
}

AutoPointSource::AutoPointSource(const DepthSamplerConfig& depth,
                                 const FeaturePointSourceConfig& features)
    : depth_(depth), features_(features) {}

PointSourceResult AutoPointSource::process(ViewId id, const Frame& frame) {
  return frame.depth_m.empty() ? features_.process(id, frame) : depth_.process(id, frame);
}

void AutoPointSource::reset() {
  depth_.reset();
  features_.reset();
}

nlohmann::json AutoPointSource::params() const {
  return {{"depth", depth_.params()}, {"features", features_.params()}};
}

const std::vector<std::string>& pointSourceNames() {
  static const std::vector<std::string> names = {"depth", "features", "map", "auto"};
  return names;
}

std::unique_ptr<PointSource> makePointSource(const std::string& name,
                                             const PointSourceParams& params) {
  if (name == "depth") return std::make_unique<DepthPointSource>(params.depth);
  if (name == "features") return std::make_unique<FeaturePointSource>(params.features);
  if (name == "map") return std::make_unique<MapPointSource>(params.map);
  if (name == "auto") return std::make_unique<AutoPointSource>(params.depth, params.features);
  std::string valid;
  for (const auto& n : pointSourceNames()) valid += (valid.empty() ? "" : ", ") + n;
  throw InvalidArgument("unknown point source '" + name + "' (valid: " + valid + ")");
}

}  // namespace view_selection
