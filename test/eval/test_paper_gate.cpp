// `--gate paper --completion paper` keeps the paper's behaviour exactly: on the built-in sequence, select_views with
// it gives bit for bit the matrix and selection that select_views gave before the matchable gate
// existed (test/data/paper_gate_sequence.json, written by that version). And the default gate,
// matchable, gives another selection on the same frames.
#include "view_selection/io/selection_io.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "support/layers.h"

namespace view_selection {
namespace {

namespace fs = std::filesystem;

int run(const std::string& command, const fs::path& log) {
  const int status = std::system((command + " > " + log.string() + " 2>&1").c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

class PaperGate : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("view_selection_paper_gate_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    const std::string tools = VIEW_SELECTION_TOOLS_DIR;
    ASSERT_EQ(run(tools + "/generate_sequence --out " + (dir_ / "seq").string() +
                      " --frames 300 --width 320 --height 240 --quiet",
                  dir_ / "generate.log"),
              0);
    ASSERT_EQ(run(tools + "/select_views --dataset " + (dir_ / "seq").string() + " --out " +
                      (dir_ / "paper").string() +
                      // the reference's keyframes are motion's (the default before issue 20);
                      // all three runs keep them, so only the gate differs
                      " --gate paper --completion paper --keyframe-policy motion --quiet"
                      " --print-sets 0",
                  dir_ / "paper.log"),
              0);
    ASSERT_EQ(run(tools + "/select_views --dataset " + (dir_ / "seq").string() + " --out " +
                      (dir_ / "default").string() + " --keyframe-policy motion --quiet --print-sets 0",
                  dir_ / "default.log"),
              0);
    ASSERT_EQ(run(tools + "/select_views --dataset " + (dir_ / "seq").string() + " --out " +
                      (dir_ / "tight").string() +
                      " --max-parallax 8 --keyframe-policy motion --quiet --print-sets 0",
                  dir_ / "tight.log"),
              0);
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static fs::path dir_;
};
fs::path PaperGate::dir_;

nlohmann::json expected() {
  std::ifstream in(fs::path(VIEW_SELECTION_SOURCE_DIR) / "test" / "data" / "paper_gate_sequence.json");
  return nlohmann::json::parse(in);
}

TEST_F(PaperGate, IsBitIdenticalToThePapersSelectionBeforeVersion2) {
  const nlohmann::json want = expected();
  const nlohmann::json got = readSelectionJson((dir_ / "paper" / "selection.json").string());
  ASSERT_EQ(got["keyframes"].size(), want["keyframe_stamps"].size());
  for (size_t i = 0; i < got["keyframes"].size(); ++i)
    EXPECT_EQ(got["keyframes"][i]["stamp"].get<double>(), want["keyframe_stamps"][i].get<double>()) << i;
  // Every entry of E to the last bit (null: +inf), and every output of the selection.
  ASSERT_EQ(got["error_resistance"].size(), want["error_resistance"].size());
  size_t finite = 0;
  for (size_t i = 0; i < want["error_resistance"].size(); ++i)
    for (size_t j = 0; j < want["error_resistance"][i].size(); ++j) {
      const auto& w = want["error_resistance"][i][j];
      const auto& g = got["error_resistance"][i][j];
      ASSERT_EQ(g.is_null(), w.is_null()) << i << "," << j;
      if (w.is_null()) continue;
      ++finite;
      ASSERT_EQ(g.get<double>(), w.get<double>()) << i << "," << j;
    }
  EXPECT_GT(finite, 500u);
  for (const char* key : {"next_views", "start_view", "order", "completed", "isolated", "final_next_views", "pairs"})
    EXPECT_EQ(got[key], want[key]) << key;
  EXPECT_EQ(got["params"]["gate"], "paper");
  EXPECT_EQ(got["params"]["max_parallax_deg"], 0.0);
  EXPECT_EQ(got["params"]["max_scale_ratio"], 0.0);
}

TEST_F(PaperGate, TheDefaultGateIsMatchableAndItsLimitsReachTheMatrix) {
  const nlohmann::json paper = readSelectionJson((dir_ / "paper" / "selection.json").string());
  const nlohmann::json ours = readSelectionJson((dir_ / "default" / "selection.json").string());
  const nlohmann::json tight = readSelectionJson((dir_ / "tight" / "selection.json").string());
  EXPECT_EQ(ours["params"]["gate"], "matchable");
  EXPECT_GT(ours["params"]["max_parallax_deg"].get<double>(), 0.0);
  EXPECT_GT(ours["params"]["max_scale_ratio"].get<double>(), 0.0);
  EXPECT_EQ(ours["keyframes"].size(), paper["keyframes"].size());  // the same keyframes
  // An 8-degree parallax limit takes points out of the wider pairs: fewer finite entries.
  EXPECT_EQ(tight["params"]["max_parallax_deg"], 8.0);
  size_t finite_paper = 0, finite_tight = 0;
  for (const auto& row : paper["error_resistance"])
    for (const auto& v : row) finite_paper += v.is_null() ? 0 : 1;
  for (const auto& row : tight["error_resistance"])
    for (const auto& v : row) finite_tight += v.is_null() ? 0 : 1;
  EXPECT_LT(finite_tight, finite_paper);
  EXPECT_GT(finite_tight, 0u);
}

}  // namespace
}  // namespace view_selection
