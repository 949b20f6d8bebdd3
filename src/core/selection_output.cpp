#include "view_selection/core/selection_output.h"

#include <cstdio>

namespace view_selection::core {

KeyframeSummary KeyframeSummary::of(const Keyframe& keyframe) {
  KeyframeSummary s;
  s.stamp = keyframe.stamp;
  s.intrinsics = keyframe.intrinsics;
  s.pose = keyframe.pose;
  s.num_points = static_cast<std::size_t>(keyframe.points.cols());
  s.revisit_of = keyframe.revisit_of;
  return s;
}

std::string defaultImageName(double stamp) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "rgb/%.6f.png", stamp);
  return buffer;
}

std::vector<std::string> SelectionOutput::imageNames() const {
  std::vector<std::string> names_by_id;
  names_by_id.reserve(keyframes.size());
  for (size_t i = 0; i < keyframes.size(); ++i) names_by_id.push_back(imageName(i));
  return names_by_id;
}

SelectionOutput makeOutput(const ErrorResistanceMatrix& matrix, const Selection& selection,
                           const SelectionConfig& config, Params params) {
  SelectionOutput s;
  s.keyframes = matrix.summaries();
  s.names = matrix.imageNames();
  s.table = matrix.table();
  s.selection = ChunkedSelection::of(selection);
  s.config = config;
  s.params = std::make_shared<const Params>(std::move(params));
  return s;
}

}  // namespace view_selection::core
