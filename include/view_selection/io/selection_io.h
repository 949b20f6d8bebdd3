// selection.json and COLMAP's pairs.txt, exactly as METHOD.md "File formats" specifies.
#pragma once

#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/pair_buckets.h"
#include "view_selection/core/selection.h"
#include "view_selection/core/selection_output.h"

#include <nlohmann/json.hpp>

#include <ostream>
#include <string>
#include <vector>

namespace view_selection::io {

inline constexpr const char* kDenseFormat = "view_selection/1";   ///< the n x n matrix
inline constexpr const char* kSparseFormat = "view_selection/2";  ///< finite entries, [j, E] a row
/// Above this many keyframes, kAuto writes view_selection/2: at 1,000 the dense matrix is 10^6
/// values (~5 MB of mostly null), at 100,000 it would be 10^10.
inline constexpr size_t kDenseFormatMaxKeyframes = 1000;
enum class JsonFormat { kAuto, kDense, kSparse };
/// Whether a selection of `keyframes` views is written as view_selection/2.
bool sparseFormatFor(size_t keyframes, JsonFormat format);

/// The selection.json document of a snapshot (parsed back from what writeSelectionJson writes,
/// so both agree). `params` holds every parameter that shaped the result. With `points` (the
/// matrix the snapshot was made of), every keyframe's sample points are included.
nlohmann::json selectionToJson(const core::SelectionOutput& snapshot,
                               const nlohmann::json& params,
                               const core::ErrorResistanceMatrix* points = nullptr,
                               JsonFormat format = JsonFormat::kAuto);
/// The same for a matrix and its selection; `dump_points` includes the points.
nlohmann::json selectionToJson(const core::ErrorResistanceMatrix& matrix,
                               const core::Selection& selection, const nlohmann::json& params,
                               bool dump_points);

/// Writes selection.json to `path`, METHOD.md's keys in METHOD.md's order, streaming (element by
/// element, the document is never built in memory); view_selection/2 above
/// kDenseFormatMaxKeyframes unless `format` says otherwise. Throws IoError when the file cannot
/// be written.
void writeSelectionJson(const std::string& path, const core::SelectionOutput& snapshot,
                        const nlohmann::json& params,
                        const core::ErrorResistanceMatrix* points = nullptr,
                        JsonFormat format = JsonFormat::kAuto);
void writeSelectionJson(std::ostream& out, const core::SelectionOutput& snapshot,
                        const nlohmann::json& params, const core::ErrorResistanceMatrix* points,
                        JsonFormat format);
void writeSelectionJson(const std::string& path, const core::ErrorResistanceMatrix& matrix,
                        const core::Selection& selection, const nlohmann::json& params,
                        bool dump_points, JsonFormat format = JsonFormat::kAuto);

/// COLMAP's match list: one "name_i name_j" line per pair. Throws IoError when a name is
/// missing, contains whitespace (COLMAP splits on it) or the file cannot be written.
void writePairsTxt(const std::string& path, const std::vector<std::string>& image_names,
                   const std::vector<std::pair<core::ViewId, core::ViewId>>& pairs);
void writePairsTxt(const std::string& path, const std::vector<std::string>& image_names,
                   const core::PairBuckets& pairs);

/// The view-pair file of the MVSNet family of MVS tools (MVSNet, CasMVSNet, ...): the view count,
/// then for each view its id and "n id score id score ...", the final next view set best first.
/// Ids are keyframe ids (the order of selection.json's keyframes); score = 1 / E[i][j] [1/m,
/// scene units], higher is better as those tools expect. Throws IoError when it cannot write.
void writeMvsPairTxt(const std::string& path, const core::SelectionOutput& snapshot);

/// Reads a selection.json back, either format (for tests and tools); throws IoError naming the file.
nlohmann::json readSelectionJson(const std::string& path);

/// The error_resistance of a selection.json of either format as a table; throws IoError when a
/// row is malformed (a dense row of the wrong length, a sparse entry naming no view).
core::ErrorResistanceTable tableFromJson(const nlohmann::json& document);
/// The same as a dense matrix (null -> +inf); for small selections.
std::vector<std::vector<double>> errorResistanceFromJson(const nlohmann::json& document);

}  // namespace view_selection::io
