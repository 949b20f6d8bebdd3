// One place that turns a point source name ("depth", "features", "map", "auto") and its
// parameters into a PointSource, for the node's ~point_source and select_views' --points.
#pragma once

#include "view_selection/core/occlusion_map.h"
#include "view_selection/core/point_source.h"
#include "view_selection/points/depth_point_source.h"
#include "view_selection/points/feature_point_source.h"
#include "view_selection/points/map_point_source.h"

#include <memory>
#include <string>
#include <vector>

namespace view_selection::points {

/// Parameters of every source; each source uses its own part.
struct PointSourceParams {
  DepthSamplerConfig depth;
  FeaturePointSourceConfig features;
  MapPointSourceConfig map;

  void visitParameters(core::ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const;
};

/// Depth back-projection for frames that carry depth, feature triangulation for the others.
/// Ids reach the feature source only for frames without depth; its tracks join those frames.
class AutoPointSource : public core::PointSource {
 public:
  AutoPointSource(const DepthSamplerConfig& depth, const FeaturePointSourceConfig& features);
  std::string name() const override { return "auto"; }
  core::PointSourceResult process(core::ViewId id, const core::Frame& frame) override;
  void reset() override;
  core::Params params() const override;

  const FeaturePointSource& features() const { return features_; }
  FeaturePointSource& features() { return features_; }

 private:
  DepthPointSource depth_;
  FeaturePointSource features_;
};

/// The parts only some sources have, found without the caller naming a concrete source: this
/// file is the one place that knows which source is which (test_layers fails on a dynamic_cast
/// to a concrete source anywhere else). Null when `source` has no such part, also for a source
/// not made by makePointSource (e.g. a test's own, or one that wraps a source made here).
/// The map input and map state of "map".
MapPointSource* mapSourceOf(core::PointSource& source);
const MapPointSource* mapSourceOf(const core::PointSource& source);
/// The feature tracks of "features", and of "auto" (its frames without depth).
FeaturePointSource* featureSourceOf(core::PointSource& source);
const FeaturePointSource* featureSourceOf(const core::PointSource& source);

/// The names makePointSource accepts.
const std::vector<std::string>& pointSourceNames();

/// "depth" | "features" | "map" | "auto". `occlusion` is the matrix's occlusion test, which the
/// map source applies too. Throws InvalidArgument for another name (listing the valid ones) or
/// for parameters out of range.
std::unique_ptr<core::PointSource> makePointSource(const std::string& name,
                                                   const PointSourceParams& params = {},
                                                   const core::OcclusionConfig& occlusion = {});

}  // namespace view_selection::points
