#include "view_selection/io/export.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/atomic_file.h"
#include "view_selection/io/selection_io.h"
#include "view_selection/io/selection_plot.h"

#include <filesystem>

namespace view_selection::io {

ExportResult exportSelection(const std::string& directory, const core::SelectionOutput& snapshot,
                             const nlohmann::json& params, const ExportOptions& options) {
  namespace fs = std::filesystem;
  if (directory.empty())
    throw core::IoError("no folder given to write selection.json and pairs.txt into");
  const fs::path dir(directory);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir))
    throw core::IoError("cannot create folder '" + directory +
                        "': " + (ec ? ec.message() : "not a folder"));
  ExportResult result;
  result.selection_json = (dir / "selection.json").string();
  result.pairs_txt = (dir / "pairs.txt").string();
  result.plot_png = (dir / "selection.png").string();
  result.mvs_pair_txt = (dir / "pair.txt").string();
  const std::vector<std::string> names = snapshot.imageNames();
  writeAtomically(result.selection_json, [&](const std::string& tmp) {
    writeSelectionJson(tmp, snapshot, params, options.points);
  });
  writeAtomically(result.pairs_txt, [&](const std::string& tmp) {
    writePairsTxt(tmp, names, snapshot.selection.pairs);
  });
  writeAtomically(result.mvs_pair_txt,
                  [&](const std::string& tmp) { writeMvsPairTxt(tmp, snapshot); });
  writeAtomically(result.plot_png, [&](const std::string& tmp) {
    writeSelectionPlot(tmp, snapshot, options.title);
  });
  return result;
}

}  // namespace view_selection::io
