// The export that view_selection_node's ~export and select_views share: selection.json, pairs.txt
// pair.txt (MVS) and selection.png of one snapshot, each written atomically.
#pragma once

#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/selection_output.h"

#include <nlohmann/json.hpp>

#include <string>

namespace view_selection::io {

struct ExportOptions {
  std::string title;  ///< heading of selection.png
  const core::ErrorResistanceMatrix* points =
      nullptr;  ///< set: selection.json lists each keyframe's points
};

struct ExportResult {
  std::string selection_json;  ///< paths written
  std::string pairs_txt;
  std::string plot_png;
  std::string mvs_pair_txt;  ///< pair.txt for MVSNet-family tools
};

/// Creates `directory` if missing and writes selection.json, pairs.txt, pair.txt (MVS) and
/// selection.png into it. Each file is complete or
/// left as it was (io::writeAtomically). Throws core::IoError naming what failed.
ExportResult exportSelection(const std::string& directory, const core::SelectionOutput& snapshot,
                             const nlohmann::json& params, const ExportOptions& options = {});

}  // namespace view_selection::io
