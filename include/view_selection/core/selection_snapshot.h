// The keyframes, the matrix E and the selection at one moment, consistent with each other: what
// every output shows (the ROS messages and markers, selection.json, pairs.txt, the plot). Made
// by ViewSelector::snapshot(); immutable once made, so readers share it without a lock.
#pragma once

#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/selection.h"
#include "view_selection/core/types.h"

#include <cstdint>
#include <string>
#include <vector>

namespace view_selection::core {

/// A keyframe without its points and depth map: what the outputs show of it.
struct KeyframeSummary {
  double stamp = 0.0;
  std::string image_name;
  PinholeIntrinsics intrinsics;
  CameraPose pose;
  std::size_t num_points = 0;

  static KeyframeSummary of(const Keyframe& keyframe);
};

struct SelectionSnapshot {
  std::vector<KeyframeSummary> keyframes;  ///< by id
  ErrorResistanceTable table;              ///< E
  Selection selection;                     ///< selectViews(table, ...)
  SelectionConfig config;                  ///< what the selection was made with
  Params params;                           ///< every parameter in force (selection.json "params")

  std::size_t size() const { return keyframes.size(); }
  /// The image names by id, as pairs.txt names them.
  std::vector<std::string> imageNames() const;
};

/// A snapshot of `matrix` with `selection` (selectViews(matrix.table(), config)).
SelectionSnapshot makeSnapshot(const ErrorResistanceMatrix& matrix, Selection selection,
                               const SelectionConfig& config, Params params = {});

}  // namespace view_selection::core
