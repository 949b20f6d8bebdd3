// The mapper hand-off end to end: select_views on the built-in sequence, then
// scripts/colmap_from_selection on its output folder makes a sparse COLMAP model from only the
// selected pairs, with most keyframes registered. Needs colmap (scripts/test installs it).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

namespace fs = std::filesystem;

int run(const std::string& command, const fs::path& log) {
  const int status = std::system((command + " > " + log.string() + " 2>&1").c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(ColmapHandOff, SelectionFolderToSparseModel) {
  if (std::system("command -v colmap > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "colmap is not installed (scripts/install_deps colmap)";
  const fs::path dir = fs::temp_directory_path() / ("view_selection_hand_off_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string tools = VIEW_SELECTION_TOOLS_DIR;
  const std::string script = std::string(VIEW_SELECTION_SOURCE_DIR) + "/scripts/colmap_from_selection";
  ASSERT_EQ(run(tools + "/generate_sequence --out " + (dir / "seq").string() +
                    " --frames 60 --width 320 --height 240 --quiet",
                dir / "generate.log"),
            0);
  ASSERT_EQ(run(tools + "/select_views --dataset " + (dir / "seq").string() + " --every 4 --out " +
                    (dir / "selection").string() + " --quiet --print-sets 0",
                dir / "select.log"),
            0);
  ASSERT_TRUE(fs::exists(dir / "selection" / "pair.txt"));  // the MVS hand-off is written too
  ASSERT_EQ(run("/usr/bin/python3 " + script + " " + (dir / "selection").string() + " --out " +
                    (dir / "model").string() + " --threads 2",
                dir / "hand_off.log"),
            0)
      << "see " << (dir / "hand_off.log");
  std::ifstream in(dir / "model" / "report.json");
  const nlohmann::json summary = nlohmann::json::parse(in);
  EXPECT_EQ(summary["keyframes"], 15);
  EXPECT_GT(summary["final_pairs"].get<int>(), 0);
  EXPECT_LE(summary["pairs_matched"].get<int>(), summary["final_pairs"].get<int>());  // only the selected pairs
  EXPECT_GE(summary["registered"].get<int>(), 12) << "see " << (dir / "model" / "colmap.log");
  EXPECT_LT(summary["reprojection_error"].get<double>(), 2.0);
  fs::remove_all(dir);
}

}  // namespace
