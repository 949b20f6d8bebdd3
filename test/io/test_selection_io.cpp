// selection.json and pairs.txt exactly as METHOD.md "File formats" specifies.
#include "view_selection/io/selection_io.h"

#include "view_selection/core/exceptions.h"

#include "support/test_support.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include "support/layers.h"

namespace view_selection {
namespace {

namespace fs = std::filesystem;
using test::lookAt;
using test::vgaIntrinsics;

fs::path freshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() /
                       ("view_selection_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

ErrorResistanceMatrix threeViews() {
  ErrorResistanceMatrix m;
  for (int v = 0; v < 3; ++v) {
    Keyframe kf;
    kf.stamp = 1000.0 + v / 30.0;
    kf.image_name = "img" + std::to_string(v) + ".jpg";
    kf.intrinsics = vgaIntrinsics();
    kf.pose = lookAt({0.3 * v, 0, 0}, {0.3, 0, 3});
    kf.points.resize(3, 20);
    for (int q = 0; q < 20; ++q)
      kf.points.col(q) = Eigen::Vector3d(0.1 * (q % 5), 0.1 * (q / 5), 3.0);
    m.addKeyframe(kf);
  }
  return m;
}

TEST(SelectionIo, JsonFollowsTheFormat) {
  const ErrorResistanceMatrix m = threeViews();
  const Selection s = selectViews(m.table(), {1, CompletionMode::kPaper});
  const fs::path dir = freshDir("json");
  const nlohmann::json params = {{"k", 1}, {"completion", "paper"}};
  writeSelectionJson((dir / "selection.json").string(), m, s, params, false);
  const nlohmann::json doc = readSelectionJson((dir / "selection.json").string());

  EXPECT_EQ(doc["format"], "view_selection/1");
  EXPECT_EQ(doc["params"], params);
  ASSERT_EQ(doc["keyframes"].size(), 3u);
  const auto& k1 = doc["keyframes"][1];
  EXPECT_EQ(k1["id"], 1);
  EXPECT_EQ(k1["stamp"].get<double>(), 1000.0 + 1 / 30.0);  // full precision round trip
  EXPECT_EQ(k1["image"], "img1.jpg");
  EXPECT_EQ(k1["position"][0].get<double>(), 0.3);
  EXPECT_EQ(k1["orientation_xyzw"].size(), 4u);
  EXPECT_EQ(k1["intrinsics"], nlohmann::json({525.0, 525.0, 319.5, 239.5, 640, 480}));
  EXPECT_FALSE(k1.contains("points"));

  const auto e = errorResistanceFromJson(doc);
  ASSERT_EQ(e.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_TRUE(doc["error_resistance"][i][i].is_null());        // +inf diagonal as null
    for (int j = 0; j < 3; ++j) EXPECT_EQ(e[i][j], m.at(i, j));  // exact doubles
  }
  EXPECT_EQ(doc["next_views"].get<std::vector<NextViewSet>>(), s.next_views);
  EXPECT_EQ(doc["start_view"], s.start_view);
  EXPECT_EQ(doc["order"].get<std::vector<ViewId>>(), s.order);
  EXPECT_EQ(doc["final_next_views"].get<std::vector<NextViewSet>>(), s.final_next_views);
  EXPECT_EQ(doc["isolated"].get<std::vector<ViewId>>(), s.isolated);
  ASSERT_EQ(doc["pairs"].size(), s.pairs.size());
  for (size_t q = 0; q < s.pairs.size(); ++q)
    EXPECT_EQ(doc["pairs"][q], nlohmann::json({s.pairs[q].first, s.pairs[q].second}));
  // Keys in METHOD.md's order.
  const std::string text = slurp(dir / "selection.json");
  size_t last = 0;
  for (const char* key : {"\"format\"", "\"params\"", "\"keyframes\"", "\"error_resistance\"",
                          "\"next_views\"", "\"start_view\"", "\"order\"", "\"completed\"",
                          "\"isolated\"", "\"final_next_views\"", "\"pairs\""}) {
    const size_t at = text.find(key);
    ASSERT_NE(at, std::string::npos) << key;
    EXPECT_GT(at, last) << key;
    last = at;
  }

  writeSelectionJson((dir / "points.json").string(), m, s, params, true);
  const auto with_points = readSelectionJson((dir / "points.json").string());
  ASSERT_EQ(with_points["keyframes"][2]["points"].size(), 20u);
  EXPECT_EQ(with_points["keyframes"][2]["points"][7], nlohmann::json({0.2, 0.1, 3.0}));
  fs::remove_all(dir);
}

TEST(SelectionIo, CompletionAndNullStartAreWritten) {
  ErrorResistanceMatrix empty;
  const fs::path dir = freshDir("null");
  writeSelectionJson((dir / "s.json").string(), empty, selectViews(empty.table(), {}), {}, false);
  const auto doc = readSelectionJson((dir / "s.json").string());
  EXPECT_TRUE(doc["start_view"].is_null());
  EXPECT_TRUE(doc["keyframes"].empty());
  ASSERT_TRUE(doc["completed"].is_array());
  EXPECT_TRUE(doc["completed"].empty());

  // k = 1: views 0 and 1 choose each other, view 2 chooses 0 but no set reaches 2, so
  // completion must bring it back; the file must say which view went into which set.
  const double inf = std::numeric_limits<double>::infinity();
  SelectionOutput snapshot;
  snapshot.table =
      ErrorResistanceTable::fromDense({{inf, 1.0, 3.0}, {1.0, inf, 4.0}, {2.0, 5.0, inf}});
  snapshot.config.k = 1;
  snapshot.config.completion = CompletionMode::kPaper;
  for (int i = 0; i < 3; ++i) {
    KeyframeSummary k;
    k.stamp = i;
    k.intrinsics = vgaIntrinsics();
    snapshot.names.push(static_cast<size_t>(i), k.stamp, std::to_string(i) + ".png");
    snapshot.keyframes.push_back(k);
  }
  snapshot.selection = ChunkedSelection::of(selectViews(snapshot.table, snapshot.config));
  ASSERT_FALSE(snapshot.selection.completed.empty()) << "the example must need completion";
  writeSelectionJson((dir / "c.json").string(), snapshot, {});
  const auto completed = readSelectionJson((dir / "c.json").string())["completed"];
  ASSERT_EQ(completed.size(), snapshot.selection.completed.size());
  for (size_t q = 0; q < completed.size(); ++q) {
    EXPECT_EQ(completed[q]["view"], snapshot.selection.completed[q].view);
    EXPECT_EQ(completed[q]["added_to"], snapshot.selection.completed[q].added_to);
  }
  EXPECT_EQ(completed[0]["view"], 2);
  fs::remove_all(dir);
}

TEST(SelectionIo, PairsTxtForColmap) {
  const fs::path dir = freshDir("pairs");
  writePairsTxt((dir / "pairs.txt").string(), {"a.jpg", "b.jpg", "sub/c.jpg"},
                {{0, 1}, {0, 2}, {1, 2}});
  EXPECT_EQ(slurp(dir / "pairs.txt"), "a.jpg b.jpg\na.jpg sub/c.jpg\nb.jpg sub/c.jpg\n");
  EXPECT_THROW(writePairsTxt((dir / "x.txt").string(), {"a b.jpg", "c.jpg"}, {{0, 1}}), IoError);
  EXPECT_THROW(writePairsTxt((dir / "x.txt").string(), {"a.jpg"}, {{0, 1}}), IoError);
  EXPECT_THROW(writePairsTxt((dir / "no" / "such" / "dir.txt").string(), {"a", "b"}, {{0, 1}}),
               IoError);
  EXPECT_THROW(readSelectionJson((dir / "missing.json").string()), IoError);
  std::ofstream(dir / "bad.json") << "{ not json";
  EXPECT_THROW(readSelectionJson((dir / "bad.json").string()), IoError);
  fs::remove_all(dir);
}

TEST(SelectionIo, MvsPairTxtListsTheFinalSetsWithInverseErrorResistance) {
  const ErrorResistanceMatrix m = threeViews();
  const SelectionOutput snap = makeOutput(m, selectViews(m.table(), {1, CompletionMode::kPaper}),
                                              {1, CompletionMode::kPaper});
  const fs::path dir = freshDir("mvs");
  writeMvsPairTxt((dir / "pair.txt").string(), snap);
  std::istringstream in(slurp(dir / "pair.txt"));
  size_t views = 0;
  in >> views;
  ASSERT_EQ(views, 3u);
  size_t listed = 0;
  for (size_t i = 0; i < views; ++i) {
    size_t id = 0, count = 0;
    in >> id >> count;
    ASSERT_EQ(id, i);
    const auto& set = snap.selection.final_next_views[i];
    ASSERT_EQ(count, set.size()) << "view " << i;
    for (size_t q = 0; q < count; ++q) {
      int j = -1;
      double score = 0.0;
      in >> j >> score;
      EXPECT_EQ(j, set[q]) << "view " << i;
      EXPECT_NEAR(score, 1.0 / m.at(static_cast<ViewId>(i), j), 1e-8 / m.at(static_cast<ViewId>(i), j));
      if (q > 0) {
        // Best first: E ascending within the selected k, so scores descend (completion last).
        EXPECT_TRUE(q >= snap.selection.next_views[i].size() || score <= 1.0 / m.at(static_cast<ViewId>(i), set[q - 1]));
      }
      ++listed;
    }
  }
  EXPECT_TRUE(in.good() || in.eof());
  EXPECT_GT(listed, 0u);
  EXPECT_THROW(writeMvsPairTxt((dir / "no" / "such" / "pair.txt").string(), snap), IoError);
}

TEST(SelectionIo, SparseFormatAboveTheThresholdReadsBackTheSameSelection) {
  // A selection larger than kDenseFormatMaxKeyframes is written as view_selection/2 (finite
  // entries only); both formats read back into the same table, and every other key is the same.
  const size_t n = kDenseFormatMaxKeyframes + 7;
  SelectionOutput snap;
  snap.table = ErrorResistanceTable(n);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  for (size_t i = 0; i < n; ++i) {
    KeyframeSummary kf;
    kf.stamp = 1000.0 + static_cast<double>(i);
    snap.names.push(i, kf.stamp, std::to_string(i) + ".png");
    kf.intrinsics = vgaIntrinsics();
    kf.pose = lookAt({0.1 * static_cast<double>(i), 0, 0}, {0, 0, 3});
    snap.keyframes.push_back(kf);
    for (int q = 0; q < 4; ++q)  // a few neighbours each, exact binary fractions and not
      snap.table.set(static_cast<ViewId>(i), static_cast<ViewId>(uni(rng) * n), 0.001 + uni(rng) / 3.0);
  }
  snap.config = {2, CompletionMode::kReachable};  // sets smaller than the rows: completion runs
  snap.selection = ChunkedSelection::of(selectViews(snap.table, snap.config));
  const nlohmann::json params = {{"k", 5}};
  const fs::path dir = freshDir("sparse");
  writeSelectionJson((dir / "auto.json").string(), snap, params);
  writeSelectionJson((dir / "dense.json").string(), snap, params, nullptr, JsonFormat::kDense);
  const auto sparse = readSelectionJson((dir / "auto.json").string());
  const auto dense = readSelectionJson((dir / "dense.json").string());
  EXPECT_EQ(sparse["format"], "view_selection/2");
  EXPECT_EQ(dense["format"], "view_selection/1");
  EXPECT_EQ(tableFromJson(sparse), snap.table);
  EXPECT_EQ(tableFromJson(dense), snap.table);
  ASSERT_EQ(sparse["error_resistance"].size(), n);
  const auto& row = snap.table.row(3);
  ASSERT_EQ(sparse["error_resistance"][3].size(), row.size());  // finite entries only, by j
  for (size_t q = 0; q < row.size(); ++q)
    EXPECT_EQ(sparse["error_resistance"][3][q], nlohmann::json({row[q].view, row[q].value}));
  for (const char* key : {"params", "keyframes", "next_views", "start_view", "initial_pair", "order",
                          "completed", "isolated", "final_next_views", "pairs"})
    EXPECT_EQ(sparse[key], dense[key]) << key;
  EXPECT_FALSE(sparse["completed"].empty());  // the random table leaves views to complete
  // The sparse file is a small fraction of the dense one.
  EXPECT_LT(fs::file_size(dir / "auto.json") * 10, fs::file_size(dir / "dense.json"));
  // Small selections stay dense unless asked.
  EXPECT_FALSE(sparseFormatFor(kDenseFormatMaxKeyframes, JsonFormat::kAuto));
  EXPECT_TRUE(sparseFormatFor(3, JsonFormat::kSparse));

  // Malformed rows are refused with a reason.
  nlohmann::json bad = sparse;
  bad["error_resistance"][0] = nlohmann::json::array({nlohmann::json::array({static_cast<int>(n), 0.5})});
  EXPECT_THROW(tableFromJson(bad), IoError);
  bad["error_resistance"][0] = nlohmann::json::array({0.5});
  EXPECT_THROW(tableFromJson(bad), IoError);
  nlohmann::json short_row = dense;
  short_row["error_resistance"][1].erase(0);
  EXPECT_THROW(tableFromJson(short_row), IoError);
  std::ofstream(dir / "foreign.json") << R"({"format": "something/3"})";
  EXPECT_THROW(readSelectionJson((dir / "foreign.json").string()), IoError);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace view_selection
