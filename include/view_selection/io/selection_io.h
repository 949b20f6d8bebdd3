// selection.json and COLMAP's pairs.txt, exactly as METHOD.md "File formats" specifies.
#pragma once

#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/selection.h"
#include "view_selection/core/selection_snapshot.h"

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace view_selection::io {

/// The selection.json document ("format": "view_selection/1") of a snapshot. `params` holds
/// every parameter that shaped the result. With `points` (the matrix the snapshot was made of),
/// every keyframe's sample points are included.
nlohmann::json selectionToJson(const core::SelectionSnapshot& snapshot,
                               const nlohmann::json& params,
                               const core::ErrorResistanceMatrix* points = nullptr);
/// The same for a matrix and its selection; `dump_points` includes the points.
nlohmann::json selectionToJson(const core::ErrorResistanceMatrix& matrix,
                               const core::Selection& selection, const nlohmann::json& params,
                               bool dump_points);

/// Writes selectionToJson(...) to `path`, METHOD.md's keys in METHOD.md's order. Throws IoError
/// when the file cannot be written.
void writeSelectionJson(const std::string& path, const core::SelectionSnapshot& snapshot,
                        const nlohmann::json& params,
                        const core::ErrorResistanceMatrix* points = nullptr);
void writeSelectionJson(const std::string& path, const core::ErrorResistanceMatrix& matrix,
                        const core::Selection& selection, const nlohmann::json& params,
                        bool dump_points);

/// COLMAP's match list: one "name_i name_j" line per pair. Throws IoError when a name is
/// missing, contains whitespace (COLMAP splits on it) or the file cannot be written.
void writePairsTxt(const std::string& path, const std::vector<std::string>& image_names,
                   const std::vector<std::pair<core::ViewId, core::ViewId>>& pairs);

/// The view-pair file of the MVSNet family of MVS tools (MVSNet, CasMVSNet, ...): the view count,
/// then for each view its id and "n id score id score ...", the final next view set best first.
/// Ids are keyframe ids (the order of selection.json's keyframes); score = 1 / E[i][j] [1/m,
/// scene units], higher is better as those tools expect. Throws IoError when it cannot write.
void writeMvsPairTxt(const std::string& path, const core::SelectionSnapshot& snapshot);

/// Reads a selection.json back (for tests and tools); throws IoError naming the file.
nlohmann::json readSelectionJson(const std::string& path);

/// The error_resistance array of a selection.json as doubles (null -> +inf).
std::vector<std::vector<double>> errorResistanceFromJson(const nlohmann::json& document);

}  // namespace view_selection::io
