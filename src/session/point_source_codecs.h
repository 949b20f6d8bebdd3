// The point sources' own state in the state file (docs/state_file.md, "Map state" and "Feature
// state"), in the layer above the point sources and the binary codec.
#pragma once

#include "view_selection/io/binary_codec.h"
#include "view_selection/points/feature_point_source.h"
#include "view_selection/points/map_point_source.h"

namespace view_selection::session {

void writeMapState(io::BinaryWriter& w, const points::MapPointSource::State& s);
points::MapPointSource::State readMapState(io::BinaryReader& r);
void writeFeatureState(io::BinaryWriter& w, const points::FeaturePointSource::State& s);
points::FeaturePointSource::State readFeatureState(io::BinaryReader& r);

}  // namespace view_selection::session
