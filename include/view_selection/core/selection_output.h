// The keyframes, the matrix E and the selection at one moment, consistent with each other: what
// every output shows (the ROS messages and markers, selection.json, pairs.txt, the plot). Made
// by ViewSelector::output(); immutable once made, so readers share it without a lock. Every
// per-keyframe list in it is chunked and shared with the selector's own (ChunkedVector), so
// making one after each keyframe costs O(n / 256) pointer copies plus the chunks that changed,
// not O(n).
#pragma once

#include "view_selection/core/chunked_selection.h"
#include "view_selection/core/chunked_vector.h"
#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/keyframe_summary.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/selection.h"
#include "view_selection/core/types.h"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace view_selection::core {

struct SelectionOutput {
  ChunkedVector<KeyframeSummary> keyframes;  ///< by id
  ImageNames names;                          ///< by id
  ErrorResistanceTable table;                ///< E
  ChunkedSelection selection;                ///< selectViews(table, config), chunked
  SelectionConfig config;                    ///< what the selection was made with
  /// Every parameter in force (selection.json "params"); shared, made once per configuration.
  std::shared_ptr<const Params> params = std::make_shared<const Params>();

  std::size_t size() const { return keyframes.size(); }
  /// The image name of keyframe i, as pairs.txt names it.
  std::string imageName(std::size_t i) const { return names.at(i, keyframes[i].stamp); }
  /// Every image name by id (O(n), for the files).
  std::vector<std::string> imageNames() const;
};

/// An output of `matrix` with `selection` (selectViews(matrix.table(), config)), for callers
/// that hold a plain Selection (tests, the io functions that take a matrix).
SelectionOutput makeOutput(const ErrorResistanceMatrix& matrix, const Selection& selection,
                           const SelectionConfig& config, Params params = {});

}  // namespace view_selection::core
