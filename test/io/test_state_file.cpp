// The state file: a session saved half way and continued in a fresh selector ends exactly where
// the uninterrupted session ends, for every point source; a truncated, corrupted, foreign or
// newer file is refused with one clear error; bad files are kept aside, never overwritten.
#include "view_selection/io/state_file.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/points/image_conversion.h"
#include "view_selection/points/point_source_factory.h"

#include "support/layers.h"
#include "support/test_support.h"
#include "support/textured_room.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <memory>

namespace view_selection {
namespace {

namespace fs = std::filesystem;
using test::lookAt;

const test::TexturedRoom& room() {
  static const test::TexturedRoom r;
  return r;
}

/// Frame q of a slow sideways walk looking at the far wall, with depth (unless `with_depth` is
/// false) and a grey image; rendered once.
Frame walkFrame(int q, bool with_depth = true) {
  static std::map<int, Frame> cache;
  auto it = cache.find(q);
  if (it == cache.end()) {
    Frame f;
    f.stamp = 10.0 + 0.1 * q;
    f.image_name = "rgb/" + std::to_string(q) + ".png";
    f.intrinsics = test::vgaIntrinsics(300.0);
    f.intrinsics.width = 320;
    f.intrinsics.height = 240;
    f.intrinsics.cx = 159.5;
    f.intrinsics.cy = 119.5;
    const Eigen::Vector3d eye(-1.0 + 0.09 * q, 0.2 - 0.02 * q, -1.0 + 0.01 * q);
    f.pose = lookAt(eye, Eigen::Vector3d(0.3 * eye.x(), 0.0, 3.0), 0.01 * q);
    cv::Mat depth;
    f.image = colourImageOf(room().render(f.intrinsics, f.pose, &depth));
    f.depth = depthImageOf(depth);
    it = cache.emplace(q, f).first;
  }
  Frame f = it->second;
  if (!with_depth) f.depth = DepthImage{};
  return f;
}

ViewSelectorConfig motionConfig() {
  ViewSelectorConfig c;
  c.keyframes.mode = KeyframeMode::kMotion;
  c.keyframes.min_translation = 0.15;  // about every other frame of the walk
  c.keyframes.min_rotation_deg = 30.0;
  c.selection.k = 3;
  return c;
}

/// The "/scale_free" suffix of a test parameter: the default policy instead of motion. It keeps
/// no state of its own (it measures against the saved keyframes), so a session continues with
/// the same keyframes too.
ViewSelectorConfig configFor(const std::string& param) {
  ViewSelectorConfig c = motionConfig();
  if (param.find("/scale_free") != std::string::npos) {
    c.keyframes = KeyframePolicyConfig{};
    c.keyframes.keyframe_parallax_deg = 2.5;  // the walk looks 3 m ahead: about every 2nd frame
  }
  return c;
}

std::unique_ptr<ViewSelector> makeSelector(const std::string& param) {
  PointSourceParams params;
  params.features.max_features = 800;
  const std::string source = param.substr(0, param.find('/'));
  return std::make_unique<ViewSelector>(configFor(param), makePointSource(source, params));
}

/// The map the "map" source gets: points on the far wall.
Eigen::Matrix3Xd wallPoints(int n, double shift) {
  Eigen::Matrix3Xd points(3, n);
  for (int i = 0; i < n; ++i)
    points.col(i) = Eigen::Vector3d(-2.5 + 5.0 * ((i * 37) % n) / n + shift,
                                    -1.2 + 2.4 * ((i * 11) % n) / n, 3.0);
  return points;
}

/// Frames [from, to): frames 2, 3, 6, 7, ... without depth for "auto" (so its feature part takes
/// keyframes too);
/// the map source gets a new map at frame 4 and at frame 9.
void feed(ViewSelector& selector, const std::string& source, int from, int to) {
  for (int q = from; q < to; ++q) {
    if (source == "map" && (q == 4 || q == 9)) {
      dynamic_cast<MapPointSource&>(selector.pointSource()).setMapPoints(wallPoints(400, 0.01 * q));
      if (q == 4) selector.applyPointUpdates();  // at 9 the updates ride with the next keyframe
    }
    selector.addFrame(walkFrame(q, source != "auto" || (q / 2) % 2 == 0));
  }
}

std::vector<uint8_t> encoded(const ViewSelector& selector) {
  SessionState state = captureSession(selector);
  state.producer = "test";
  state.saved_at = 1.0;
  return encodeState(state);
}

class ContinueExactly : public ::testing::TestWithParam<std::string> {};

TEST_P(ContinueExactly, SavedHalfWayAndContinuedEqualsUninterrupted) {
  const std::string param = GetParam();
  const std::string source = param.substr(0, param.find('/'));
  constexpr int kFrames = 14, kSaved = 7;
  auto whole = makeSelector(param);
  feed(*whole, source, 0, kFrames);

  auto first = makeSelector(param);
  feed(*first, source, 0, kSaved);
  ASSERT_GE(first->matrix().size(), 3u);
  const std::vector<uint8_t> bytes = encoded(*first);
  const SessionState decoded = decodeState(bytes.data(), bytes.size());
  // The file holds everything: decoding and encoding again gives the same bytes.
  {
    SessionState again = decoded;
    EXPECT_EQ(encodeState(again), bytes);
  }
  auto resumed = makeSelector(param);
  restoreSession(*resumed, decoded);
  EXPECT_EQ(encoded(*resumed), bytes) << "restored state differs from the saved one";
  feed(*resumed, source, kSaved, kFrames);

  ASSERT_EQ(resumed->matrix().size(), whole->matrix().size());
  EXPECT_GT(whole->matrix().size(), first->matrix().size());
  // The policy thinned the walk (it is no every_frame in disguise), the same way both times.
  EXPECT_LT(whole->matrix().size(), static_cast<size_t>(kFrames)) << param;
  EXPECT_TRUE(resumed->matrix().table() == whole->matrix().table()) << "E differs";
  EXPECT_GT(whole->matrix().table().finiteCount(), 0u);
  for (size_t i = 0; i < whole->matrix().size(); ++i) {
    const Keyframe& a = whole->matrix().keyframe(static_cast<ViewId>(i));
    const Keyframe& b = resumed->matrix().keyframe(static_cast<ViewId>(i));
    EXPECT_EQ(a.stamp, b.stamp) << i;
    EXPECT_TRUE(a.points.cols() == b.points.cols() && a.points == b.points) << "points of " << i;
  }
  const Selection s1 = whole->select(), s2 = resumed->select();
  EXPECT_EQ(s1.next_views, s2.next_views);
  EXPECT_EQ(s1.pairs, s2.pairs);
  EXPECT_EQ(s1.order, s2.order);
  // Whatever the source keeps (tracks, map) ends the same too.
  EXPECT_EQ(encoded(*resumed), encoded(*whole));
}

INSTANTIATE_TEST_SUITE_P(EverySource, ContinueExactly,
                         ::testing::Values("depth", "features", "map", "auto", "depth/scale_free",
                                           "features/scale_free", "map/scale_free",
                                           "auto/scale_free"),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           std::string name = info.param;
                           for (char& c : name)
                             if (c == '/') c = '_';
                           return name;
                         });

TEST(StateFile, WrittenAtomicallyAndReadBack) {
  const fs::path dir = fs::temp_directory_path() / ("state_file_test_" + std::to_string(getpid()));
  fs::create_directories(dir);
  auto selector = makeSelector("depth");
  feed(*selector, "depth", 0, 6);
  SessionState state = captureSession(*selector);
  state.producer = "test";
  state.statistics.frames_received = 6;
  state.statistics.frames_offered = 6;
  state.statistics.dropped["no_pose"] = 2;
  state.statistics.last_frame_stamp = 10.5;
  state.pair_sequence = 1234567890123ull;
  const std::string path = (dir / "state.vss").string();
  writeStateFile(path, state);
  const SessionState read = readStateFile(path);
  EXPECT_EQ(read.producer, "test");
  // The pair stream's sequence continues after a restart; a file without it reads as before.
  EXPECT_EQ(read.pair_sequence, std::optional<uint64_t>(1234567890123ull));
  state.pair_sequence.reset();
  const std::vector<uint8_t> without = encodeState(state);
  EXPECT_FALSE(decodeState(without.data(), without.size()).pair_sequence.has_value());
  EXPECT_TRUE(read.statistics == state.statistics);
  EXPECT_EQ(read.selector.keyframes.size(), selector->matrix().size());
  // Only the file itself is left: no temporary beside it.
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir)) files += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(files, 1u);
  // Into a folder that does not exist: an IoError, nothing created.
  EXPECT_THROW(writeStateFile((dir / "missing" / "state.vss").string(), state), core::IoError);
  EXPECT_FALSE(fs::exists(dir / "missing"));
  fs::remove_all(dir);
}

/// The message of the StateFileError that decoding `bytes` throws ("" when none is thrown).
std::string decodeError(const std::vector<uint8_t>& bytes) {
  try {
    decodeState(bytes.data(), bytes.size(), "f");
  } catch (const StateFileError& e) {
    return e.what();
  }
  return "";
}

TEST(StateFile, TruncatedCorruptedForeignAndNewerFilesAreRefused) {
  auto selector = makeSelector("depth");
  feed(*selector, "depth", 0, 4);
  const std::vector<uint8_t> bytes = encoded(*selector);
  ASSERT_GT(bytes.size(), 1000u);

  EXPECT_NE(decodeError({}).find("empty"), std::string::npos);
  for (size_t n : {size_t{1}, size_t{7}, size_t{8}, size_t{31}, size_t{32}, size_t{33},
                   bytes.size() / 2, bytes.size() - 1}) {
    const std::string e = decodeError(std::vector<uint8_t>(bytes.begin(), bytes.begin() + n));
    EXPECT_NE(e.find("truncated"), std::string::npos) << n << " bytes: " << e;
  }
  {
    std::vector<uint8_t> longer = bytes;
    longer.push_back(0);
    EXPECT_NE(decodeError(longer).find("trailing"), std::string::npos);
  }
  // One flipped bit anywhere is caught by a checksum.
  for (size_t at : {size_t{9}, size_t{20}, size_t{40}, bytes.size() / 3, bytes.size() - 1}) {
    std::vector<uint8_t> flipped = bytes;
    flipped[at] ^= 0x10;
    const std::string e = decodeError(flipped);
    EXPECT_NE(e.find("corrupted"), std::string::npos) << "byte " << at << ": " << e;
  }
  // Foreign files.
  const std::string png = "\x89PNG\r\n\x1a\n0000000000000000000000000000000000";
  EXPECT_NE(decodeError(std::vector<uint8_t>(png.begin(), png.end())).find("not a view_selection"),
            std::string::npos);
  const std::string text = "keyframes: 3\n";
  EXPECT_NE(decodeError(std::vector<uint8_t>(text.begin(), text.end())).find("not a"),
            std::string::npos);
  // A newer format version (with a header checksum that matches).
  {
    std::vector<uint8_t> newer = bytes;
    newer[8] = 2;
    const uint32_t crc = crc32(newer.data(), 28);
    for (int b = 0; b < 4; ++b) newer[28 + b] = static_cast<uint8_t>(crc >> (8 * b));
    EXPECT_NE(decodeError(newer).find("format version 2"), std::string::npos) << decodeError(newer);
  }
  EXPECT_EQ(decodeError(bytes), "");
}

TEST(StateFile, AnotherPointSourceCannotContinueASession) {
  auto depth = makeSelector("depth");
  feed(*depth, "depth", 0, 4);
  const SessionState state = captureSession(*depth);
  auto features = makeSelector("features");
  feed(*features, "features", 0, 2);
  const size_t before = features->matrix().size();
  try {
    restoreSession(*features, state);
    FAIL() << "a depth session restored into a feature source";
  } catch (const core::InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("'depth'"), std::string::npos) << e.what();
  }
  EXPECT_EQ(features->matrix().size(), before) << "a refused session changes nothing";

  // The same source with other parameters: its points would differ, so it is refused too.
  PointSourceParams coarse;
  coarse.depth.grid = 32;
  ViewSelector other(motionConfig(), makePointSource("depth", coarse));
  EXPECT_THROW(restoreSession(other, state), core::InvalidArgument);
}

TEST(StateFile, InconsistentContentIsRefused) {
  auto selector = makeSelector("depth");
  feed(*selector, "depth", 0, 4);
  SessionState state = captureSession(*selector);
  ASSERT_FALSE(state.selector.rows.empty());
  state.selector.rows[0].push_back({99, 1.0});  // a column that does not exist
  auto target = makeSelector("depth");
  EXPECT_THROW(restoreSession(*target, state), core::InvalidInput);
  EXPECT_EQ(target->matrix().size(), 0u);
}

TEST(StateFile, BadFilesAreKeptAsideNeverOverwritten) {
  const fs::path dir = fs::temp_directory_path() / ("state_aside_test_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "state.vss").string();
  std::vector<std::string> aside;
  for (int n = 0; n < 3; ++n) {
    std::ofstream(path) << "bad " << n;
    aside.push_back(moveAside(path));
    EXPECT_FALSE(fs::exists(path));
  }
  // Three names (the same second gives "-1", "-2"), each with its own content.
  for (int n = 0; n < 3; ++n) {
    std::ifstream in(aside[static_cast<size_t>(n)]);
    std::string word, number;
    in >> word >> number;
    EXPECT_EQ(number, std::to_string(n)) << aside[static_cast<size_t>(n)];
    EXPECT_NE(aside[static_cast<size_t>(n)].find("state.vss.bad-"), std::string::npos);
  }
  EXPECT_THROW(moveAside(path), core::IoError);  // nothing to move
  fs::remove_all(dir);
}

TEST(StateFile, Crc32IsZlibs) {
  const std::string check = "123456789";
  EXPECT_EQ(crc32(reinterpret_cast<const uint8_t*>(check.data()), check.size()), 0xCBF43926u);
}

}  // namespace
}  // namespace view_selection
