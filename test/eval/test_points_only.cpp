// select_views on a points-only folder (generate_sequence --points-only): every record becomes
// a keyframe, the selection is written, and the summary gives the time per stage and peak RSS.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace {

namespace fs = std::filesystem;

int run(const std::string& command, const fs::path& log) {
  const int status = std::system((command + " > " + log.string() + " 2>&1").c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(PointsOnly, SelectViewsRunsOnAGeneratedPointsFolder) {
  const fs::path dir =
      fs::temp_directory_path() / ("view_selection_points_only_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string tools = VIEW_SELECTION_TOOLS_DIR;
  ASSERT_EQ(run(tools + "/generate_sequence --points-only --frames 400 --seed 3 --out " +
                    (dir / "walk").string() + " --quiet",
                dir / "generate.log"),
            0);
  EXPECT_EQ(run(tools + "/generate_sequence --points-only --noise 1 --out " +
                    (dir / "bad").string(),
                dir / "bad.log"),
            2) << "an option that does not apply must be refused";
  ASSERT_EQ(run(tools + "/select_views --dataset " + (dir / "walk").string() + " --out " +
                    // the records are a SLAM session's keyframes: every one is a keyframe
                    (dir / "selection").string() + " --every 1 --quiet --print-sets 0",
                dir / "select.log"),
            0);
  std::ifstream log_in(dir / "select.log");
  const std::string log(std::istreambuf_iterator<char>(log_in), {});
  EXPECT_NE(log.find("keyframes   400"), std::string::npos) << log;
  EXPECT_NE(log.find("peak RSS"), std::string::npos) << log;
  EXPECT_NE(log.find("| matrix "), std::string::npos) << log;
  std::ifstream json_in(dir / "selection" / "selection.json");
  const nlohmann::json json = nlohmann::json::parse(json_in);
  ASSERT_EQ(json["keyframes"].size(), 400u);
  EXPECT_GT(json["pairs"].size(), 400u);  // a connected walk: at least about one pair a view
  fs::remove_all(dir);
}

}  // namespace
