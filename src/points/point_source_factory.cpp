#include "view_selection/points/point_source_factory.h"

#include "view_selection/core/exceptions.h"

namespace view_selection::points {

void PointSourceParams::visitParameters(core::ParameterVisitor& v) {
  depth.visitParameters(v);
  features.visitParameters(v);
  map.visitParameters(v);
}

void PointSourceParams::validate() const {
  depth.validate();
  features.validate();
  map.validate();
}

AutoPointSource::AutoPointSource(const DepthSamplerConfig& depth,
                                 const FeaturePointSourceConfig& features)
    : depth_(depth), features_(features) {}

core::PointSourceResult AutoPointSource::process(core::ViewId id, const core::Frame& frame) {
  return frame.depth.empty() ? features_.process(id, frame) : depth_.process(id, frame);
}

void AutoPointSource::reset() {
  depth_.reset();
  features_.reset();
}

core::Params AutoPointSource::params() const {
  return {{"depth", false, true, depth_.params()}, {"features", false, true, features_.params()}};
}

MapPointSource* mapSourceOf(core::PointSource& source) {
  return dynamic_cast<MapPointSource*>(&source);
}

const MapPointSource* mapSourceOf(const core::PointSource& source) {
  return dynamic_cast<const MapPointSource*>(&source);
}

FeaturePointSource* featureSourceOf(core::PointSource& source) {
  if (auto* f = dynamic_cast<FeaturePointSource*>(&source)) return f;
  if (auto* a = dynamic_cast<AutoPointSource*>(&source)) return &a->features();
  return nullptr;
}

const FeaturePointSource* featureSourceOf(const core::PointSource& source) {
  if (auto* f = dynamic_cast<const FeaturePointSource*>(&source)) return f;
  if (auto* a = dynamic_cast<const AutoPointSource*>(&source)) return &a->features();
  return nullptr;
}

const std::vector<std::string>& pointSourceNames() {
  static const std::vector<std::string> names = {"depth", "features", "map", "auto"};
  return names;
}

std::unique_ptr<core::PointSource> makePointSource(const std::string& name,
                                                   const PointSourceParams& params,
                                                   const core::OcclusionConfig& occlusion) {
  if (name == "depth") return std::make_unique<DepthPointSource>(params.depth);
  if (name == "features") return std::make_unique<FeaturePointSource>(params.features);
  if (name == "map") {
    MapPointSourceConfig map = params.map;
    map.occlusion = occlusion;
    return std::make_unique<MapPointSource>(map);
  }
  if (name == "auto") return std::make_unique<AutoPointSource>(params.depth, params.features);
  std::string valid;
  for (const auto& n : pointSourceNames()) valid += (valid.empty() ? "" : ", ") + n;
  throw core::InvalidArgument("unknown point source '" + name + "' (valid: " + valid + ")");
}

}  // namespace view_selection::points
