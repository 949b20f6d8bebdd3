// Tests on the real data in ../shared/data (beside the repository). Without it such a test skips
// or falls back to synthetic frames, and says so here: the line goes to $VIEW_SELECTION_SKIP_LOG
// when set (scripts/test sets it, counts the lines in its summary and fails when the data folder
// exists but a test still went without it).
#pragma once

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>

namespace view_selection::test {

/// ../shared/data/<name> beside the source folder, when it holds `probe`; otherwise records
/// that `test` ran without it and returns nothing.
inline std::optional<std::filesystem::path> realData(const std::string& name,
                                                     const std::string& test,
                                                     const std::string& probe = "rgb.txt") {
  const std::filesystem::path root =
      std::filesystem::path(VIEW_SELECTION_SOURCE_DIR).parent_path() / "shared" / "data" / name;
  if (std::filesystem::exists(root / probe)) return root;
  if (const char* log = std::getenv("VIEW_SELECTION_SKIP_LOG"); log && *log)
    std::ofstream(log, std::ios::app)
        << test << ": no real data (" << root.string() << " absent)\n";
  return std::nullopt;
}

}  // namespace view_selection::test
