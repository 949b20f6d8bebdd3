// The fuzz targets (fuzz/) in the normal suite: every committed corpus input and every input
// that once made a target crash (fuzz/regressions/<target>/) runs through the same function
// libFuzzer calls; a crash, an exception other than the expected errors, or a broken invariant
// fails here.
#include "../../fuzz/fuzz_target.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

namespace {

namespace fs = std::filesystem;

std::vector<fs::path> inputsOf(const std::string& target, size_t* regressions) {
  std::vector<fs::path> files;
  const fs::path root = fs::path(VIEW_SELECTION_SOURCE_DIR) / "fuzz";
  for (const char* kind : {"corpus", "regressions"}) {
    const fs::path dir = root / kind / target;
    if (!fs::is_directory(dir)) continue;
    for (const auto& e : fs::directory_iterator(dir)) {
      if (!e.is_regular_file() || e.path().filename().string()[0] == '.') continue;
      files.push_back(e.path());
      if (std::string(kind) == "regressions") ++*regressions;
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

TEST(FuzzInputs, EveryTargetHasACorpus) {
  const auto& targets = view_selection::fuzz::targets();
  EXPECT_EQ(targets.size(), 6u);
  for (const auto& [name, run] : targets) {
    size_t regressions = 0;
    EXPECT_FALSE(inputsOf(name, &regressions).empty()) << "no fuzz/corpus/" << name;
  }
}

TEST(FuzzInputs, CorpusAndRegressionsRunCleanly) {
  for (const auto& [name, run] : view_selection::fuzz::targets()) {
    size_t regressions = 0;
    const std::vector<fs::path> files = inputsOf(name, &regressions);
    for (const fs::path& file : files) {
      std::ifstream in(file, std::ios::binary);
      const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                       std::istreambuf_iterator<char>());
      SCOPED_TRACE(file.string());
      EXPECT_NO_THROW(run(bytes.data(), bytes.size()));
    }
    std::printf("[ fuzz     ] %s: %zu inputs (%zu regressions)\n", name.c_str(), files.size(),
                regressions);
  }
}

}  // namespace
