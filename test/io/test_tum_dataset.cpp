// TUM RGB-D reader: list parsing and its error messages, camera YAML, associate.py's greedy
// association, the dataset loader, and the two real data sets when present.
#include "view_selection/io/tum_dataset.h"

#include "view_selection/core/exceptions.h"

#include "support/real_data.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <tuple>
#include <vector>
#include "support/layers.h"

namespace view_selection {
namespace {

namespace fs = std::filesystem;
using Pairs = std::vector<std::pair<size_t, size_t>>;

// ---------------------------------------------------------------------------------------------
// Fixture: a fresh temporary folder per test.

class TumTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string pattern = (fs::temp_directory_path() / "vs_tum_XXXXXX").string();
    ASSERT_NE(mkdtemp(pattern.data()), nullptr);
    dir_ = pattern;
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  /// Writes `content` to dir_/relative (creating folders) and returns the full path.
  std::string write(const std::string& relative, const std::string& content) const {
    const fs::path p = dir_ / relative;
    fs::create_directories(p.parent_path());
    std::ofstream out(p, std::ios::binary);
    out << content;
    return p.string();
  }
  void touch(const fs::path& folder, const std::string& relative) const {
    const fs::path p = folder / relative;
    fs::create_directories(p.parent_path());
    std::ofstream out(p, std::ios::binary);
    out << "x";
  }

  fs::path dir_;
};

/// Expects `fn` to throw E whose message contains every one of `parts`.
template <typename E, typename Fn>
void expectThrowWith(Fn&& fn, const std::vector<std::string>& parts) {
  try {
    fn();
    ADD_FAILURE() << "expected an exception containing '" << parts.front() << "'";
  } catch (const E& e) {
    const std::string what = e.what();
    for (const std::string& part : parts) {
      EXPECT_NE(what.find(part), std::string::npos) << "'" << part << "' not in: " << what;
    }
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// associateStamps

/// associate.py written out literally: every pair under the tolerance, sorted by
/// (difference, a, b), taken greedily. O(n m); the reference for the windowed implementation.
Pairs associateReference(const std::vector<double>& a, const std::vector<double>& b,
                         double max_difference) {
  std::vector<std::tuple<double, double, double, size_t, size_t>> candidates;
  for (size_t i = 0; i < a.size(); ++i) {
    for (size_t j = 0; j < b.size(); ++j) {
      const double d = std::abs(a[i] - b[j]);
      if (d < max_difference) candidates.emplace_back(d, a[i], b[j], i, j);
    }
  }
  std::sort(candidates.begin(), candidates.end());
  std::vector<bool> used_a(a.size()), used_b(b.size());
  Pairs out;
  for (const auto& c : candidates) {
    const size_t i = std::get<3>(c), j = std::get<4>(c);
    if (used_a[i] || used_b[j]) continue;
    used_a[i] = used_b[j] = true;
    out.emplace_back(i, j);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(TumAssociate, WorkedExampleSortedByFirstIndex) {
  // a is unsorted on purpose; each b is 10 ms after one a.
  const std::vector<double> a = {3.0, 1.0, 2.0, 5.0};
  const std::vector<double> b = {1.01, 2.01, 3.01, 4.0};
  // 5.0 has nothing within 0.02; 4.0 has nothing either.
  EXPECT_EQ(associateStamps(a, b, 0.02), (Pairs{{0, 2}, {1, 0}, {2, 1}}));
}

TEST(TumAssociate, GreedyBestFirstNotInListOrder) {
  // a[0]=0.00 is 0.05 from b[0]; a[1]=0.06 is 0.01 from b[0]. The best pair (a1,b0) is taken
  // first, so a[0] stays unmatched although walking a in order would have given it b[0]
  // (and then a[1] would be unmatched: b[1] is 0.14 away).
  EXPECT_EQ(associateStamps({0.0, 0.06}, {0.05, 0.2}, 0.1), (Pairs{{1, 0}}));

  // A chain: b[1] is nearest to a[1], which frees b[0] for a[0] only because (a1,b1) goes first.
  // Differences (binary-exact): a0b0 0.25, a1b0 0.25, a1b1 0.125, a0b1 0.625.
  EXPECT_EQ(associateStamps({1.0, 1.5}, {1.25, 1.625}, 0.5), (Pairs{{0, 0}, {1, 1}}));
  // Without b[1] the tie (a0b0 vs a1b0, both 0.25) goes to the smaller first stamp, a0.
  EXPECT_EQ(associateStamps({1.0, 1.5}, {1.25}, 0.5), (Pairs{{0, 0}}));
}

TEST(TumAssociate, TiesGoToSmallerStampNotSmallerIndex) {
  // Same tie as above with a listed in reverse: the stamp 1.0 (now index 1) still wins.
  EXPECT_EQ(associateStamps({1.5, 1.0}, {1.25}, 0.5), (Pairs{{1, 0}}));
  // Tie on the second list: 0.75 and 1.25 are both 0.25 from 1.0; the smaller stamp 0.75 wins
  // even though it is listed second.
  EXPECT_EQ(associateStamps({1.0}, {1.25, 0.75}, 0.5), (Pairs{{0, 1}}));
}

TEST(TumAssociate, ToleranceIsStrict) {
  EXPECT_TRUE(associateStamps({0.0}, {0.5}, 0.5).empty());
  EXPECT_EQ(associateStamps({0.0}, {0.5}, 0.500001), (Pairs{{0, 0}}));
  EXPECT_TRUE(associateStamps({}, {1.0}, 1.0).empty());
  EXPECT_TRUE(associateStamps({1.0}, {}, 1.0).empty());
  EXPECT_THROW(associateStamps({1.0}, {1.0}, -0.1), InvalidArgument);
  EXPECT_THROW(associateStamps({1.0}, {1.0}, std::nan("")), InvalidArgument);
}

TEST(TumAssociate, MatchesLiteralAssociatePyOnRandomLists) {
  std::mt19937 rng(42);
  for (int trial = 0; trial < 200; ++trial) {
    // Stamps on a 1/64 s grid so that exact ties in difference are common.
    std::uniform_int_distribution<int> count(0, 40), tick(0, 300);
    std::vector<double> a(count(rng)), b(count(rng));
    for (double& s : a) s = tick(rng) / 64.0;
    for (double& s : b) s = tick(rng) / 64.0;
    const double max_difference = std::uniform_int_distribution<int>(0, 8)(rng) / 64.0 + 1e-9;
    const Pairs got = associateStamps(a, b, max_difference);
    ASSERT_EQ(got, associateReference(a, b, max_difference)) << "trial " << trial;
    // Each element used at most once.
    std::vector<int> seen_a(a.size()), seen_b(b.size());
    for (const auto& [i, j] : got) {
      ASSERT_EQ(++seen_a[i], 1);
      ASSERT_EQ(++seen_b[j], 1);
      ASSERT_LT(std::abs(a[i] - b[j]), max_difference);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// readTumImageList / readTumTrajectory

TEST_F(TumTest, ImageListSkipsCommentsBlankLinesAndCrLf) {
  const std::string path = write("rgb.txt",
                                 "# color images\r\n"
                                 "# timestamp filename\r\n"
                                 "\r\n"
                                 "1305031102.175304 rgb/1305031102.175304.png\r\n"
                                 "   \t\r\n"
                                 "  # indented comment\n"
                                 "1305031102.211214\trgb/1305031102.211214.png\n"
                                 "+7 last.png");  // no final newline
  const std::vector<TumImageEntry> list = readTumImageList(path);
  ASSERT_EQ(list.size(), 3u);
  EXPECT_DOUBLE_EQ(list[0].stamp, 1305031102.175304);
  EXPECT_EQ(list[0].path, "rgb/1305031102.175304.png");  // no '\r' left
  EXPECT_DOUBLE_EQ(list[1].stamp, 1305031102.211214);
  EXPECT_EQ(list[1].path, "rgb/1305031102.211214.png");
  EXPECT_DOUBLE_EQ(list[2].stamp, 7.0);
  EXPECT_EQ(list[2].path, "last.png");
}

TEST_F(TumTest, TrajectoryColumnOrderAndNormalisedQuaternion) {
  // qw slightly off unit length (7-digit files): accepted and normalised.
  const std::string path = write("groundtruth.txt",
                                 "# timestamp tx ty tz qx qy qz qw\r\n"
                                 "1.5 0.1 -0.2 0.3 0.1 0.2 0.3 0.95\r\n"
                                 "2.5 1 2 3 0 0 0 1.02\n");
  const std::vector<TumPoseEntry> poses = readTumTrajectory(path);
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_DOUBLE_EQ(poses[0].stamp, 1.5);
  EXPECT_TRUE(poses[0].pose.position.isApprox(Eigen::Vector3d(0.1, -0.2, 0.3)));
  const double n = std::sqrt(0.01 + 0.04 + 0.09 + 0.95 * 0.95);
  EXPECT_NEAR(poses[0].pose.orientation.x(), 0.1 / n, 1e-12);
  EXPECT_NEAR(poses[0].pose.orientation.y(), 0.2 / n, 1e-12);
  EXPECT_NEAR(poses[0].pose.orientation.z(), 0.3 / n, 1e-12);
  EXPECT_NEAR(poses[0].pose.orientation.w(), 0.95 / n, 1e-12);
  EXPECT_NEAR(poses[1].pose.orientation.norm(), 1.0, 1e-15);
  EXPECT_NEAR(poses[1].pose.orientation.w(), 1.0, 1e-15);
}

struct MalformedCase {
  const char* name;
  bool trajectory;
  const char* content;
  int line;
  const char* says;
};

class TumMalformedLine : public TumTest, public ::testing::WithParamInterface<MalformedCase> {};

TEST_P(TumMalformedLine, NamesFileLineAndProblem) {
  const MalformedCase& c = GetParam();
  const std::string path = write(c.trajectory ? "groundtruth.txt" : "rgb.txt", c.content);
  auto read = [&] {
    if (c.trajectory) {
      readTumTrajectory(path);
    } else {
      readTumImageList(path);
    }
  };
  expectThrowWith<IoError>(read, {path, "line " + std::to_string(c.line) + ":", c.says});
}

INSTANTIATE_TEST_SUITE_P(
    Cases, TumMalformedLine,
    ::testing::Values(
        MalformedCase{"ImageMissingPath", false, "# c\n1.0 a.png\n\n2.0\n", 4, "found 1"},
        MalformedCase{"ImageExtraColumn", false, "1.0 a.png\n2.0 my image.png\n", 2,
                      "must not contain whitespace"},
        MalformedCase{"ImageStampNotNumber", false, "1.0 a.png\nabc b.png\n", 2,
                      "stamp 'abc' is not a number"},
        MalformedCase{"ImageStampTrailingJunk", false, "1.0x a.png\n", 1,
                      "stamp '1.0x' is not a number"},
        MalformedCase{"ImageStampNaN", false, "\r\nnan a.png\r\n", 2, "is not finite"},
        MalformedCase{"ImageStampInf", false, "# x\n-inf a.png\n", 2, "is not finite"},
        MalformedCase{"ImageDuplicateStamp", false, "1.0 a.png\n2.0 b.png\n1.000 c.png\n", 3,
                      "duplicate stamp 1.000 (already on line 1)"},
        MalformedCase{"PoseSevenColumns", true, "# h\n1.0 0 0 0 0 0 1\n", 2, "found 7"},
        MalformedCase{"PoseNineColumns", true, "1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1 5\n", 2,
                      "found 9"},
        MalformedCase{"PoseNotNumber", true, "1.0 0 abc 0 0 0 0 1\n", 1,
                      "ty 'abc' is not a number"},
        MalformedCase{"PoseNaN", true, "1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 nan\n", 2,
                      "qw 'nan' is not finite"},
        MalformedCase{"PoseInf", true, "1.0 0 0 inf 0 0 0 1\n", 1, "tz 'inf' is not finite"},
        MalformedCase{"PoseZeroQuaternion", true, "1.0 0 0 0 0 0 0 1\r\n2.0 0 0 0 0 0 0 0\r\n", 2,
                      "has norm 0"},
        MalformedCase{"PoseLongQuaternion", true, "1.0 0 0 0 0 0 0 2\n", 1, "unit quaternion"},
        MalformedCase{"PoseDuplicateStamp", true, "1.0 0 0 0 0 0 0 1\n1.0 1 0 0 0 0 0 1\n", 2,
                      "duplicate stamp 1.0 (already on line 1)"}),
    [](const ::testing::TestParamInfo<MalformedCase>& info) { return info.param.name; });

TEST_F(TumTest, MissingListFileIsNamed) {
  const std::string path = (dir_ / "nothing.txt").string();
  expectThrowWith<IoError>([&] { readTumImageList(path); }, {path, "does not exist"});
  expectThrowWith<IoError>([&] { readTumTrajectory(path); }, {path, "does not exist"});
  expectThrowWith<IoError>([&] { readTumImageList(dir_.string()); }, {dir_.string(), "folder"});
}

// ---------------------------------------------------------------------------------------------
// camera YAML and TUM defaults

TEST_F(TumTest, FlatCameraYaml) {
  const std::string path = write("camera.yaml",
                                 "# pinhole\nfx: 585.5\nfy: 586\ncx: 320.25\ncy: 240\nwidth: 640\n"
                                 "height: 480\n");
  const PinholeIntrinsics k = loadCameraYaml(path);
  EXPECT_DOUBLE_EQ(k.fx, 585.5);
  EXPECT_DOUBLE_EQ(k.fy, 586.0);
  EXPECT_DOUBLE_EQ(k.cx, 320.25);
  EXPECT_DOUBLE_EQ(k.cy, 240.0);
  EXPECT_EQ(k.width, 640);
  EXPECT_EQ(k.height, 480);
}

TEST_F(TumTest, RosCalibrationYaml) {
  const std::string path = write("ost.yaml",
                                 "image_width: 752\n"
                                 "image_height: 480\n"
                                 "camera_name: narrow_stereo\n"
                                 "camera_matrix:\n"
                                 "  rows: 3\n"
                                 "  cols: 3\n"
                                 "  data: [461.6, 0, 363.0, 0, 460.3, 248.1, 0, 0, 1]\n"
                                 "distortion_model: plumb_bob\n"
                                 "distortion_coefficients:\n"
                                 "  rows: 1\n"
                                 "  cols: 5\n"
                                 "  data: [-0.28, 0.07, 0.0002, 0.00002, 0]\n"
                                 "rectification_matrix:\n"
                                 "  rows: 3\n"
                                 "  cols: 3\n"
                                 "  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
                                 "projection_matrix:\n"
                                 "  rows: 3\n"
                                 "  cols: 4\n"
                                 "  data: [400, 0, 300, 0, 0, 400, 200, 0, 0, 0, 1, 0]\n");
  const PinholeIntrinsics k = loadCameraYaml(path);
  EXPECT_DOUBLE_EQ(k.fx, 461.6);  // camera_matrix, not projection_matrix
  EXPECT_DOUBLE_EQ(k.fy, 460.3);
  EXPECT_DOUBLE_EQ(k.cx, 363.0);
  EXPECT_DOUBLE_EQ(k.cy, 248.1);
  EXPECT_EQ(k.width, 752);
  EXPECT_EQ(k.height, 480);
}

TEST_F(TumTest, CameraYamlErrorsNameFileAndKey) {
  const std::string flat_ok = "fx: 500\nfy: 500\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n";
  struct Case {
    std::string content, key, says;
  };
  const std::vector<Case> cases = {
      {"fx: 500\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n", "'fy'", "missing key"},
      {"fx: 500\nfy: 500\ncx: abc\ncy: 240\nwidth: 640\nheight: 480\n", "'cx'", "not a number"},
      {"fx: 500\nfy: [1, 2]\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n", "'fy'", "not a number"},
      {"fx: -500\nfy: 500\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n", "'fx'",
       "not a valid focal length"},
      {"fx: 0\nfy: 500\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n", "'fx'",
       "not a valid focal length"},
      {"fx: 500\nfy: .nan\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n", "'fy'", "not finite"},
      {"fx: 500\nfy: 500\ncx: 320\ncy: 240\nwidth: 640.5\nheight: 480\n", "'width'",
       "positive whole number"},
      {"fx: 500\nfy: 500\ncx: 320\ncy: 240\nwidth: 640\nheight: 0\n", "'height'",
       "positive whole number"},
      {"image_width: 640\nimage_height: 480\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
       "  data: [500, 0, 320, 0, 500, 240, 0, 0]\n",
       "'camera_matrix/data'", "9 numbers"},
      {"image_width: 640\ncamera_matrix:\n  data: [500, 0, 320, 0, 500, 240, 0, 0, 1]\n",
       "'image_height'", "missing key"},
      {"image_width: 640\nimage_height: 480\ncamera_matrix:\n  rows: 3\n  cols: 3\n",
       "'camera_matrix/data'", "missing key"},
      {"image_width: 640\nimage_height: 480\ncamera_matrix:\n"
       "  data: [500, 0, 320, 0, x, 240, 0, 0, 1]\n",
       "'camera_matrix/data[4]'", "not a number"},
      {"image_width: 640\nimage_height: 480\ncamera_matrix:\n"
       "  data: [-500, 0, 320, 0, 500, 240, 0, 0, 1]\n",
       "camera_matrix/data[0] (fx)", "not a valid focal length"},
      {"image_width: 640\nimage_height: 480\ncamera_matrix:\n"
       "  data: [500, 0, 0, 0, 500, 0, 320, 240, 1]\n",
       "'camera_matrix/data'", "[fx 0 cx 0 fy cy 0 0 1]"},
      {"fx: [unclosed\n", "not valid YAML", ""},
      {"- 1\n- 2\n", "not a map", ""},
  };
  ASSERT_NO_THROW(loadCameraYaml(write("ok.yaml", flat_ok)));
  for (size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE("case " + std::to_string(i));
    const std::string path = write("bad" + std::to_string(i) + ".yaml", cases[i].content);
    expectThrowWith<IoError>([&] { loadCameraYaml(path); }, {path, cases[i].key, cases[i].says});
  }
  const std::string missing = (dir_ / "none.yaml").string();
  expectThrowWith<IoError>([&] { loadCameraYaml(missing); }, {missing, "does not exist"});
}

TEST(TumDefaults, ChosenByFolderName) {
  const auto fr1 = tumDefaultIntrinsics("rgbd_dataset_freiburg1_xyz");
  ASSERT_TRUE(fr1.has_value());
  EXPECT_DOUBLE_EQ(fr1->fx, 517.3);
  EXPECT_DOUBLE_EQ(fr1->fy, 516.5);
  EXPECT_DOUBLE_EQ(fr1->cx, 318.6);
  EXPECT_DOUBLE_EQ(fr1->cy, 255.3);
  EXPECT_EQ(fr1->width, 640);
  EXPECT_EQ(fr1->height, 480);

  const auto fr2 = tumDefaultIntrinsics("fr2_desk");
  ASSERT_TRUE(fr2.has_value());
  EXPECT_DOUBLE_EQ(fr2->fx, 520.9);
  EXPECT_DOUBLE_EQ(fr2->fy, 521.0);
  EXPECT_DOUBLE_EQ(fr2->cx, 325.1);
  EXPECT_DOUBLE_EQ(fr2->cy, 249.7);

  const auto fr3 = tumDefaultIntrinsics("RGBD_Dataset_Freiburg3_Long_Office_Household");
  ASSERT_TRUE(fr3.has_value());
  EXPECT_DOUBLE_EQ(fr3->fx, 535.4);
  EXPECT_DOUBLE_EQ(fr3->fy, 539.2);
  EXPECT_DOUBLE_EQ(fr3->cx, 320.1);
  EXPECT_DOUBLE_EQ(fr3->cy, 247.6);
  EXPECT_DOUBLE_EQ(tumDefaultIntrinsics("FR3_office")->fx, 535.4);

  EXPECT_FALSE(tumDefaultIntrinsics("redkitchen-0-499").has_value());
  EXPECT_FALSE(tumDefaultIntrinsics("freiburg").has_value());
  EXPECT_FALSE(tumDefaultIntrinsics("").has_value());
  EXPECT_FALSE(tumDefaultIntrinsics("fr1_vs_fr2").has_value());  // ambiguous
}

// ---------------------------------------------------------------------------------------------
// loadTumDataset

const char* const kCamera = "fx: 500\nfy: 501\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n";

/// A pose line at `stamp` with position (x, 0, 0) and identity rotation.
std::string poseLine(const std::string& stamp, double x) {
  return stamp + " " + std::to_string(x) + " 0 0 0 0 0 1\n";
}

TEST_F(TumTest, LoadsAndAssociatesSmallDataset) {
  const fs::path root = dir_ / "scene";
  write("scene/camera.yaml", kCamera);
  // rgb listed out of order; 4.000 has a depth image but no pose, 5.000 has no depth image.
  write("scene/rgb.txt",
        "# color images\n"
        "2.000000 rgb/2.000000.png\n"
        "1.000000 rgb/1.000000.png\n"
        "3.000000 rgb/3.000000.png\n"
        "4.000000 rgb/4.000000.png\n"
        "5.000000 rgb/5.000000.png\n");
  write("scene/depth.txt",
        "1.005000 depth/1.005000.png\n"
        "2.015000 depth/2.015000.png\n"
        "2.990000 depth/2.990000.png\n"
        "3.995000 depth/3.995000.png\n"
        "5.050000 depth/5.050000.png\n");  // 50 ms away from 5.0: outside 0.02
  // Denser ground truth; rgb 1.0 -> 1.004 (nearest), 2.0 -> 1.992 and 3.0 -> 3.006.
  write("scene/groundtruth.txt", poseLine("0.990000", 0.99) + poseLine("1.004000", 1.004) +
                                     poseLine("1.016000", 1.016) + poseLine("1.992000", 1.992) +
                                     poseLine("2.009000", 2.009) + poseLine("3.006000", 3.006) +
                                     poseLine("4.100000", 4.1) + poseLine("5.000000", 5.0));
  for (const char* f : {"rgb/1.000000.png", "rgb/2.000000.png", "rgb/3.000000.png",
                        "depth/1.005000.png", "depth/2.015000.png", "depth/2.990000.png"}) {
    touch(root, f);
  }

  const TumDataset ds = loadTumDataset(root.string());
  EXPECT_EQ(ds.root, root.string());
  EXPECT_TRUE(ds.has_depth);
  EXPECT_EQ(ds.intrinsics_source, "camera.yaml");
  EXPECT_DOUBLE_EQ(ds.intrinsics.fy, 501.0);
  EXPECT_DOUBLE_EQ(ds.depth_metres_per_unit, 1.0 / 5000.0);
  EXPECT_EQ(ds.rgb_entries, 5u);
  EXPECT_EQ(ds.dropped_without_depth, 1u);  // 5.0
  EXPECT_EQ(ds.dropped_without_pose, 1u);   // 4.0
  EXPECT_EQ(ds.image_dir, "rgb");
  ASSERT_EQ(ds.frames.size(), 3u);

  const double stamps[3] = {1.0, 2.0, 3.0};
  const double depth_stamps[3] = {1.005, 2.015, 2.99};
  const double pose_stamps[3] = {1.004, 1.992, 3.006};
  for (size_t k = 0; k < 3; ++k) {
    SCOPED_TRACE("frame " + std::to_string(k));
    const TumFrame& f = ds.frames[k];
    EXPECT_DOUBLE_EQ(f.stamp, stamps[k]);
    EXPECT_DOUBLE_EQ(f.depth_stamp, depth_stamps[k]);
    EXPECT_DOUBLE_EQ(f.pose_stamp, pose_stamps[k]);
    EXPECT_NEAR(f.pose.position.x(), pose_stamps[k], 1e-9);  // the pose of that line
  }
  EXPECT_EQ(ds.frames[1].rgb_path, "rgb/2.000000.png");
  EXPECT_EQ(ds.frames[1].depth_path, "depth/2.015000.png");
  EXPECT_EQ(ds.imageName(ds.frames[0]), "1.000000.png");
  EXPECT_EQ(ds.imageName(ds.frames[2]), "3.000000.png");
}

TEST_F(TumTest, PoseIsNearestNotUniqueAndTiesGoEarlier) {
  const fs::path root = dir_ / "scene";
  write("scene/camera.yaml", kCamera);
  // Sparse ground truth: both 1.0 and 1.015 take the pose at 1.01 (not unique-assigned).
  // 2.0 is exactly between 1.9921875 and 2.0078125 (binary-exact): the earlier one wins.
  write("scene/rgb.txt", "1.0 a.png\n1.015 b.png\n2.0 c.png\n");
  write("scene/groundtruth.txt",
        poseLine("2.0078125", 3.0) + poseLine("1.01", 1.0) + poseLine("1.9921875", 2.0));
  for (const char* f : {"a.png", "b.png", "c.png"}) touch(root, f);

  const TumDataset ds = loadTumDataset(root.string());
  EXPECT_FALSE(ds.has_depth);
  EXPECT_EQ(ds.image_dir, "");
  ASSERT_EQ(ds.frames.size(), 3u);
  EXPECT_DOUBLE_EQ(ds.frames[0].pose_stamp, 1.01);
  EXPECT_DOUBLE_EQ(ds.frames[1].pose_stamp, 1.01);
  EXPECT_DOUBLE_EQ(ds.frames[2].pose_stamp, 1.9921875);
  EXPECT_DOUBLE_EQ(ds.frames[2].pose.position.x(), 2.0);
  EXPECT_TRUE(ds.frames[0].depth_path.empty());
  EXPECT_EQ(ds.imageName(ds.frames[1]), "b.png");
}

TEST_F(TumTest, RgbDepthAssociationIsUniqueAndGreedy) {
  const fs::path root = dir_ / "scene";
  write("scene/camera.yaml", kCamera);
  // Depth 1.012 is nearer to rgb 1.02 (0.008) than to rgb 1.0 (0.012), so rgb 1.0 loses it and
  // has nothing else: dropped without depth even though it had a depth image within 0.02.
  write("scene/rgb.txt", "1.0 rgb/a.png\n1.02 rgb/b.png\n");
  write("scene/depth.txt", "1.012 d/a.png\n");
  write("scene/groundtruth.txt", poseLine("1.0", 0) + poseLine("1.02", 1));
  touch(root, "rgb/a.png");
  touch(root, "rgb/b.png");
  touch(root, "d/a.png");
  const TumDataset ds = loadTumDataset(root.string());
  ASSERT_EQ(ds.frames.size(), 1u);
  EXPECT_DOUBLE_EQ(ds.frames[0].stamp, 1.02);
  EXPECT_EQ(ds.frames[0].depth_path, "d/a.png");
  EXPECT_EQ(ds.dropped_without_depth, 1u);
  EXPECT_EQ(ds.dropped_without_pose, 0u);

  // A tolerance below every gap leaves no frame, and the message says which tolerance.
  TumDatasetOptions tight;
  tight.max_time_difference = 1e-4;
  expectThrowWith<InvalidInput>([&] { loadTumDataset(root.string(), tight); },
                                {"no frame left", "0.0001 s", "2 rgb images"});
}

TEST_F(TumTest, MissingFolderAndListsAreExplained) {
  const std::string missing = (dir_ / "nope").string();
  expectThrowWith<IoError>([&] { loadTumDataset(missing); },
                           {"dataset folder '" + missing + "' does not exist"});

  const fs::path root = dir_ / "scene";
  fs::create_directories(root);
  expectThrowWith<IoError>([&] { loadTumDataset(root.string()); }, {root.string(), "rgb.txt"});
  write("scene/rgb.txt", "1.0 a.png\n");
  expectThrowWith<IoError>([&] { loadTumDataset(root.string()); },
                           {root.string(), "groundtruth.txt", "pose"});

  const std::string file = write("plain", "x");
  expectThrowWith<IoError>([&] { loadTumDataset(file); }, {file, "not a folder"});
  TumDatasetOptions bad;
  bad.max_time_difference = 0.0;
  EXPECT_THROW(loadTumDataset(root.string(), bad), InvalidArgument);
}

TEST_F(TumTest, MalformedLineInDatasetNamesThatFile) {
  const fs::path root = dir_ / "scene";
  write("scene/camera.yaml", kCamera);
  write("scene/rgb.txt", "1.0 a.png\n");
  const std::string gt = write("scene/groundtruth.txt", "# gt\n1.0 0 0 0 0 0 0\n");
  expectThrowWith<IoError>([&] { loadTumDataset(root.string()); }, {gt, "line 2:", "found 7"});
  write("scene/groundtruth.txt", poseLine("1.0", 0));
  const std::string depth = write("scene/depth.txt", "1.0\n");
  expectThrowWith<IoError>([&] { loadTumDataset(root.string()); }, {depth, "line 1:"});
}

TEST_F(TumTest, MissingImageFilesAreCountedAndFirstNamed) {
  const fs::path root = dir_ / "scene";
  write("scene/camera.yaml", kCamera);
  write("scene/rgb.txt", "3.0 rgb/3.png\n1.0 rgb/1.png\n2.0 rgb/2.png\n");
  write("scene/depth.txt", "1.0 depth/1.png\n2.0 depth/2.png\n3.0 depth/3.png\n");
  write("scene/groundtruth.txt", poseLine("1.0", 0) + poseLine("2.0", 0) + poseLine("3.0", 0));
  touch(root, "rgb/1.png");
  touch(root, "depth/1.png");
  touch(root, "rgb/3.png");
  // Missing, in stamp order: rgb/2.png, depth/2.png, depth/3.png.
  expectThrowWith<IoError>([&] { loadTumDataset(root.string()); },
                           {"3 of the 6", (root / "rgb/2.png").string()});
  fs::create_directories(root / "depth/3.png");  // a folder is not an image
  touch(root, "rgb/2.png");
  touch(root, "depth/2.png");
  expectThrowWith<IoError>([&] { loadTumDataset(root.string()); },
                           {"1 of the 6", (root / "depth/3.png").string()});
}

TEST_F(TumTest, NothingLeftIsInvalidInputWithReason) {
  const fs::path root = dir_ / "scene";
  write("scene/camera.yaml", kCamera);
  write("scene/rgb.txt", "# only comments\n\n");
  write("scene/groundtruth.txt", poseLine("1.0", 0));
  expectThrowWith<InvalidInput>([&] { loadTumDataset(root.string()); },
                                {root.string(), "rgb.txt lists no images"});

  write("scene/rgb.txt", "1.0 a.png\n2.0 b.png\n");
  write("scene/groundtruth.txt", poseLine("1.5", 0));
  expectThrowWith<InvalidInput>(
      [&] { loadTumDataset(root.string()); },
      {"no frame left", "within 0.02 s", "2 have no ground-truth pose", "1.500000"});

  write("scene/groundtruth.txt", "# empty\n");
  expectThrowWith<InvalidInput>([&] { loadTumDataset(root.string()); },
                                {"groundtruth.txt lists no poses"});

  write("scene/groundtruth.txt", poseLine("1.0", 0) + poseLine("2.0", 0));
  write("scene/depth.txt", "7.0 d.png\n");
  expectThrowWith<InvalidInput>([&] { loadTumDataset(root.string()); },
                                {"2 have no depth image", "0.02 s"});
}

TEST_F(TumTest, DefaultIntrinsicsFromFolderName) {
  for (const std::string suffix : {"", "/"}) {
    const fs::path root = dir_ / "rgbd_dataset_freiburg2_desk";
    write("rgbd_dataset_freiburg2_desk/rgb.txt", "1.0 rgb/a.png\n");
    write("rgbd_dataset_freiburg2_desk/groundtruth.txt", poseLine("1.0", 0));
    touch(root, "rgb/a.png");
    const TumDataset ds = loadTumDataset(root.string() + suffix);
    EXPECT_EQ(ds.intrinsics_source, "TUM freiburg2 defaults");
    EXPECT_DOUBLE_EQ(ds.intrinsics.fx, 520.9);
    EXPECT_DOUBLE_EQ(ds.intrinsics.cy, 249.7);
    EXPECT_EQ(ds.intrinsics.width, 640);
  }
  // camera.yaml overrides the name.
  write("rgbd_dataset_freiburg2_desk/camera.yaml", kCamera);
  const TumDataset ds = loadTumDataset((dir_ / "rgbd_dataset_freiburg2_desk").string());
  EXPECT_EQ(ds.intrinsics_source, "camera.yaml");
  EXPECT_DOUBLE_EQ(ds.intrinsics.fx, 500.0);

  const fs::path other = dir_ / "my_scene";
  write("my_scene/rgb.txt", "1.0 a.png\n");
  write("my_scene/groundtruth.txt", poseLine("1.0", 0));
  touch(other, "a.png");
  expectThrowWith<IoError>([&] { loadTumDataset(other.string()); },
                           {other.string(), "camera.yaml", "fx, fy, cx, cy, width, height"});
  // A broken camera.yaml is an error, not a reason to fall back to defaults.
  write("my_scene/camera.yaml", "fx: 500\n");
  expectThrowWith<IoError>([&] { loadTumDataset(other.string()); }, {"camera.yaml", "'fy'"});
}

TEST_F(TumTest, ImageDirIsTheCommonDirectory) {
  struct Case {
    std::vector<std::string> paths;
    std::string image_dir;
    std::vector<std::string> names;
  };
  const std::vector<Case> cases = {
      {{"rgb/1.png", "rgb/2.png"}, "rgb", {"1.png", "2.png"}},
      {{"data/rgb/1.png", "data/rgb/2.png"}, "data/rgb", {"1.png", "2.png"}},
      {{"images/a/1.png", "images/b/2.png"}, "images", {"a/1.png", "b/2.png"}},
      // Same characters, different folders: no common directory.
      {{"rgb1/1.png", "rgb2/2.png"}, "", {"rgb1/1.png", "rgb2/2.png"}},
      {{"a/b/1.png", "a/bc/2.png"}, "a", {"b/1.png", "bc/2.png"}},
      {{"rgb/1.png", "2.png"}, "", {"rgb/1.png", "2.png"}},
      {{"1.png", "2.png"}, "", {"1.png", "2.png"}},
  };
  for (size_t c = 0; c < cases.size(); ++c) {
    SCOPED_TRACE("case " + std::to_string(c));
    const std::string name = "scene" + std::to_string(c);
    const fs::path root = dir_ / name;
    write(name + "/camera.yaml", kCamera);
    std::string rgb, gt;
    for (size_t k = 0; k < cases[c].paths.size(); ++k) {
      rgb += std::to_string(k + 1) + ".0 " + cases[c].paths[k] + "\n";
      gt += poseLine(std::to_string(k + 1) + ".0", 0);
      touch(root, cases[c].paths[k]);
    }
    write(name + "/rgb.txt", rgb);
    write(name + "/groundtruth.txt", gt);
    const TumDataset ds = loadTumDataset(root.string());
    EXPECT_EQ(ds.image_dir, cases[c].image_dir);
    ASSERT_EQ(ds.frames.size(), cases[c].names.size());
    for (size_t k = 0; k < ds.frames.size(); ++k) {
      EXPECT_EQ(ds.imageName(ds.frames[k]), cases[c].names[k]);
      // root/image_dir/name is the file.
      EXPECT_TRUE(fs::is_regular_file(root / ds.image_dir / ds.imageName(ds.frames[k])));
    }
  }
  TumDataset ds;
  ds.image_dir = "rgb";
  TumFrame outside;
  outside.rgb_path = "depth/1.png";
  EXPECT_THROW(ds.imageName(outside), InvalidArgument);
}

// ---------------------------------------------------------------------------------------------
// The real data sets (tests run with the repository root as working directory).

/// First and last data-line stamps of a list, as written.
std::pair<double, double> firstAndLastStamp(const fs::path& list) {
  std::ifstream in(list);
  std::string line;
  std::vector<double> stamps;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    stamps.push_back(std::stod(line.substr(0, line.find(' '))));
  }
  return {stamps.front(), stamps.back()};
}

TEST(TumRealData, RedKitchen) {
  const auto data = test::realData("redkitchen-0-499", "TumRealData.RedKitchen");
  if (!data) GTEST_SKIP() << "no real data: ../shared/data/redkitchen-0-499 not present";
  const fs::path root = *data;
  const TumDataset ds = loadTumDataset(root.string());
  EXPECT_EQ(ds.frames.size(), 500u);
  EXPECT_EQ(ds.rgb_entries, 500u);
  EXPECT_TRUE(ds.has_depth);
  EXPECT_EQ(ds.dropped_without_depth, 0u);
  EXPECT_EQ(ds.dropped_without_pose, 0u);
  EXPECT_EQ(ds.intrinsics_source, "camera.yaml");
  EXPECT_DOUBLE_EQ(ds.intrinsics.fx, 585.0);
  EXPECT_EQ(ds.intrinsics.width, 640);
  EXPECT_EQ(ds.image_dir, "rgb");
  const auto [first, last] = firstAndLastStamp(root / "rgb.txt");
  EXPECT_DOUBLE_EQ(ds.frames.front().stamp, first);
  EXPECT_DOUBLE_EQ(ds.frames.back().stamp, last);
  EXPECT_EQ(ds.imageName(ds.frames.front()), "1000.000000.jpg");
  for (size_t k = 0; k < ds.frames.size(); ++k) {
    const TumFrame& f = ds.frames[k];
    ASSERT_FALSE(f.depth_path.empty());
    ASSERT_LT(std::abs(f.depth_stamp - f.stamp), 0.02);
    ASSERT_LT(std::abs(f.pose_stamp - f.stamp), 0.02);
    ASSERT_NEAR(f.pose.orientation.norm(), 1.0, 1e-12);
    if (k > 0) {
      ASSERT_LT(ds.frames[k - 1].stamp, f.stamp);
    }
  }
}

TEST(TumRealData, DtuScan24) {
  const auto data = test::realData("dtu-scan24", "TumRealData.DtuScan24");
  if (!data) GTEST_SKIP() << "no real data: ../shared/data/dtu-scan24 not present";
  const fs::path root = *data;
  const TumDataset ds = loadTumDataset(root.string());
  EXPECT_EQ(ds.frames.size(), 49u);
  EXPECT_FALSE(ds.has_depth);
  EXPECT_EQ(ds.intrinsics.width, 384);
  EXPECT_EQ(ds.intrinsics_source, "camera.yaml");
  EXPECT_EQ(ds.image_dir, "rgb");
  const auto [first, last] = firstAndLastStamp(root / "rgb.txt");
  EXPECT_DOUBLE_EQ(ds.frames.front().stamp, first);
  EXPECT_DOUBLE_EQ(ds.frames.back().stamp, last);
  for (const TumFrame& f : ds.frames) {
    EXPECT_TRUE(f.depth_path.empty());
    EXPECT_DOUBLE_EQ(f.pose_stamp, f.stamp);  // stamps are view indices, exact
  }
}

}  // namespace
}  // namespace view_selection
