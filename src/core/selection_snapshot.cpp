#include "view_selection/core/selection_snapshot.h"

namespace view_selection::core {

KeyframeSummary KeyframeSummary::of(const Keyframe& keyframe) {
  KeyframeSummary s;
  s.stamp = keyframe.stamp;
  s.image_name = keyframe.image_name;
  s.intrinsics = keyframe.intrinsics;
  s.pose = keyframe.pose;
  s.num_points = static_cast<std::size_t>(keyframe.points.cols());
  return s;
}

std::vector<std::string> SelectionSnapshot::imageNames() const {
  std::vector<std::string> names;
  names.reserve(keyframes.size());
  for (const KeyframeSummary& k : keyframes) names.push_back(k.image_name);
  return names;
}

SelectionSnapshot makeSnapshot(const ErrorResistanceMatrix& matrix, Selection selection,
                               const SelectionConfig& config, Params params) {
  SelectionSnapshot s;
  s.keyframes.reserve(matrix.size());
  for (size_t i = 0; i < matrix.size(); ++i)
    s.keyframes.push_back(KeyframeSummary::of(matrix.keyframe(static_cast<ViewId>(i))));
  s.table = matrix.table();
  s.selection = std::move(selection);
  s.config = config;
  s.params = std::move(params);
  return s;
}

}  // namespace view_selection::core
