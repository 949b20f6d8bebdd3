// The state file: a session saved half way and continued in a fresh selector ends exactly where
// the uninterrupted session ends, for every point source; a truncated, corrupted, foreign or
// newer file is refused with one clear error; bad files are kept aside, never overwritten.
#include "view_selection/session/state_file.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/io/crc32.h"
#include "view_selection/io/file_ops.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/session/capture.h"
#include "view_selection/session/delta_tracker.h"
#include "view_selection/session/journal.h"

#include "support/layers.h"
#include "support/test_support.h"
#include "support/textured_room.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <random>

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

TEST(StateFile, RevisitLinksAreKeptInTheFileAndInAJournalRecord) {
  // Keyframe::revisit_of (a revisit recognised from the images) in the optional RVST section:
  // read back into the keyframes of a whole state and of a journal record; a file without the
  // section has none; a link to a keyframe not before its own is refused.
  auto selector = makeSelector("depth");
  feed(*selector, "depth", 0, 12);
  SessionState state = captureSession(*selector);
  ASSERT_GE(state.selector.keyframes.size(), 4u);
  std::vector<uint8_t> bytes = encodeState(state);
  for (const core::Keyframe& k : decodeState(bytes.data(), bytes.size()).selector.keyframes)
    EXPECT_EQ(k.revisit_of, -1);
  state.selector.keyframes[3].revisit_of = 1;
  state.selector.keyframes[2].revisit_of = 0;
  bytes = encodeState(state);
  const SessionState read = decodeState(bytes.data(), bytes.size());
  for (size_t i = 0; i < read.selector.keyframes.size(); ++i)
    EXPECT_EQ(read.selector.keyframes[i].revisit_of, i == 3 ? 1 : i == 2 ? 0 : -1) << i;
  EXPECT_TRUE(read.revisit_links.empty());

  SessionDelta delta;
  delta.keyframe_count = state.selector.keyframes.size();
  for (size_t i = 1; i < state.selector.keyframes.size(); ++i)
    delta.keyframes.emplace_back(static_cast<core::ViewId>(i), state.selector.keyframes[i]);
  delta.rest = state;
  delta.rest.selector.keyframes.clear();
  delta.rest.selector.rows.clear();
  SessionState replayed = state;
  for (core::Keyframe& k : replayed.selector.keyframes) k.revisit_of = -1;
  replayed.base_id = 7;
  const std::vector<uint8_t> record = encodeJournalRecord(7, 0, delta);
  const JournalReplay r = replayJournal(replayed, record.data(), record.size());
  EXPECT_EQ(r.error, "");
  EXPECT_EQ(r.records, 1u);
  EXPECT_EQ(replayed.selector.keyframes[3].revisit_of, 1);
  EXPECT_EQ(replayed.selector.keyframes[2].revisit_of, 0);
  EXPECT_EQ(replayed.selector.keyframes[1].revisit_of, -1);

  state.selector.keyframes[2].revisit_of = 2;  // itself
  bytes = encodeState(state);
  EXPECT_THROW(decodeState(bytes.data(), bytes.size()), StateFileError);
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

// ---------------------------------------------------------------------------------------------
// The journal: records of what changed since the last save, replayed over the base file.

/// A state as bytes, with what differs between equal sessions (producer, time, base id) fixed.
std::vector<uint8_t> canonical(SessionState state) {
  state.producer = "test";
  state.saved_at = 1.0;
  state.base_id.reset();
  return encodeState(state);
}

/// A journal of four records after a base of the first frames, with the states each record
/// leads to (canonical); the second record also carries a loop closure (keyframes moved).
struct Journal {
  SessionState base;
  std::vector<uint8_t> bytes;
  std::vector<size_t> starts;                  // of each record
  std::vector<std::vector<uint8_t>> expected;  // the state after each record
  std::vector<SessionDelta> deltas;
};

Journal makeJournal(const std::string& source, uint64_t base_id) {
  Journal j;
  auto selector = makeSelector(source);
  feed(*selector, source, 0, 3);
  j.base = captureSession(*selector);
  j.base.base_id = base_id;
  DeltaTracker tracker;
  tracker.markSaved(*selector);
  const int cuts[] = {3, 5, 8, 10, 14};
  for (int c = 0; c + 1 < 5; ++c) {
    feed(*selector, source, cuts[c], cuts[c + 1]);
    if (c == 1 && selector->matrix().size() >= 3) {
      // A loop closure moves keyframes 0 and 1: their keyframes and rows change.
      std::vector<std::pair<ViewId, CameraPose>> moved;
      for (ViewId id : {0, 1}) {
        CameraPose p = selector->matrix().keyframe(id).pose;
        p.position += Eigen::Vector3d(0.02, -0.01, 0.0);
        moved.emplace_back(id, p);
      }
      selector->correctPoses(moved);
    }
    SessionDelta d = tracker.capture(*selector);
    d.rest.statistics.frames_offered = static_cast<uint64_t>(cuts[c + 1]);
    d.rest.pair_sequence = 100 + static_cast<uint64_t>(c);
    j.starts.push_back(j.bytes.size());
    const std::vector<uint8_t> record = encodeJournalRecord(base_id, static_cast<uint64_t>(c), d);
    j.bytes.insert(j.bytes.end(), record.begin(), record.end());
    SessionState whole = captureSession(*selector);
    whole.statistics = d.rest.statistics;
    whole.pair_sequence = d.rest.pair_sequence;
    j.expected.push_back(canonical(whole));
    j.deltas.push_back(std::move(d));
  }
  return j;
}

class JournalReplaysExactly : public ::testing::TestWithParam<std::string> {};

TEST_P(JournalReplaysExactly, BasePlusJournalEqualsAWholeCapture) {
  const Journal j = makeJournal(GetParam(), 42);
  // Only what changed: the records together hold fewer keyframes than a whole capture each.
  EXPECT_LT(j.deltas.back().keyframes.size(), j.base.selector.keyframes.size() + 8);
  SessionState state = j.base;
  const JournalReplay r = replayJournal(state, j.bytes.data(), j.bytes.size());
  EXPECT_EQ(r.error, "");
  EXPECT_EQ(r.records, 4u);
  EXPECT_EQ(r.good_bytes, j.bytes.size());
  EXPECT_EQ(canonical(state), j.expected.back());
  EXPECT_EQ(state.pair_sequence, std::optional<uint64_t>(103));
  // The replayed state continues in a selector, as the node does.
  auto resumed = makeSelector(GetParam());
  restoreSession(*resumed, state);
  EXPECT_EQ(canonical(captureSession(*resumed)),
            [&] {
              SessionState plain = state;
              plain.statistics = {};
              plain.pair_sequence.reset();
              return canonical(plain);
            }());
  // Two records merged (as the keeper merges records waiting) give the same state.
  SessionState merged = j.base;
  applyDelta(merged, j.deltas[0]);
  SessionDelta both = j.deltas[1];
  SessionDelta rest = j.deltas[2];
  mergeDelta(both, rest);
  applyDelta(merged, both);
  applyDelta(merged, j.deltas[3]);
  EXPECT_EQ(canonical(merged), j.expected.back());
}

INSTANTIATE_TEST_SUITE_P(EverySource, JournalReplaysExactly,
                         ::testing::Values("depth", "features", "map"));

TEST(StateJournal, ATornTailIsDroppedWhereverTheLastRecordIsCut) {
  const Journal j = makeJournal("depth", 7);
  const size_t last = j.starts.back();
  ASSERT_GT(j.bytes.size() - last, 100u);
  // Every byte of the header and of the record's first and last 512 bytes, every 7th between.
  for (size_t cut = last + 1; cut < j.bytes.size();
       cut += (cut < last + 512 || cut + 512 > j.bytes.size()) ? 1 : 7) {
    SessionState state = j.base;
    const JournalReplay r = replayJournal(state, j.bytes.data(), cut);
    ASSERT_NE(r.error, "") << "cut at " << cut;
    ASSERT_EQ(r.records, 3u) << "cut at " << cut;
    ASSERT_EQ(r.good_bytes, last) << "cut at " << cut;
    ASSERT_EQ(canonical(state), j.expected[2]) << "cut at " << cut;
  }
  // A changed byte anywhere in the last record: the same.
  for (size_t at = last; at < j.bytes.size(); at += 97) {
    std::vector<uint8_t> bad = j.bytes;
    bad[at] ^= 0x10;
    SessionState state = j.base;
    const JournalReplay r = replayJournal(state, bad.data(), bad.size());
    ASSERT_NE(r.error, "") << "byte " << at;
    ASSERT_EQ(r.records, 3u) << "byte " << at;
    ASSERT_EQ(canonical(state), j.expected[2]) << "byte " << at;
  }
  // Cut exactly between records: a clean end, no error.
  SessionState state = j.base;
  const JournalReplay r = replayJournal(state, j.bytes.data(), last);
  EXPECT_EQ(r.error, "");
  EXPECT_EQ(canonical(state), j.expected[2]);
}

TEST(StateJournal, RecordsOfAnotherBaseAreIgnored) {
  const Journal j = makeJournal("depth", 7);
  SessionState state = j.base;
  state.base_id = 8;  // a newer base: it holds what the records add
  const JournalReplay r = replayJournal(state, j.bytes.data(), j.bytes.size());
  EXPECT_EQ(r.error, "");
  EXPECT_EQ(r.records, 0u);
  EXPECT_EQ(r.stale, 4u);
  EXPECT_EQ(canonical(state), canonical(j.base));
  state.base_id.reset();  // a file before the journal: records never apply
  EXPECT_EQ(replayJournal(state, j.bytes.data(), j.bytes.size()).records, 0u);
}

/// Points handed in from outside, for long sessions without rendering.
class GivenPoints : public core::PointSource {
 public:
  std::string name() const override { return "depth"; }  // the state of a source without any
  core::PointSourceResult process(ViewId, const Frame&) override {
    core::PointSourceResult r;
    r.points = next;
    return r;
  }
  void reset() override {}
  Eigen::Matrix3Xd next;
};

TEST(StateJournal, ALongSessionReplaysExactlyAcrossVersionChunks) {
  // 700 keyframes (three chunks of 256 versions), records every 9 keyframes, corrections that
  // move keyframes of earlier chunks in between: base + journal equals a whole capture.
  auto points = std::make_unique<GivenPoints>();
  GivenPoints* given = points.get();
  ViewSelectorConfig config;
  config.keyframes.mode = KeyframeMode::kEveryFrame;
  ViewSelector selector(config, std::move(points));
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  const auto add = [&](int q) {
    Frame f;
    f.stamp = 1.0 + q;
    f.image_name = std::to_string(q);
    f.intrinsics = test::vgaIntrinsics();
    const Eigen::Vector3d eye(0.0, 0.0, 0.5 * q);
    f.pose = lookAt(eye, eye + Eigen::Vector3d(0.0, 0.0, 1.0));
    given->next.resize(3, 40);
    for (int c = 0; c < 40; ++c)
      given->next.col(c) = eye + Eigen::Vector3d(2.0 * uni(rng), 1.5 * uni(rng), 5.0 + uni(rng));
    selector.addFrame(f);
  };
  for (int q = 0; q < 20; ++q) add(q);
  SessionState state = captureSession(selector);
  state.base_id = 5;
  DeltaTracker tracker;
  tracker.markSaved(selector);
  std::vector<uint8_t> journal;
  uint64_t index = 0;
  for (int q = 20; q < 700; ++q) {
    add(q);
    if (q % 97 == 0) {
      // A loop closure moves a keyframe of the first chunk and one of the last.
      std::vector<std::pair<ViewId, CameraPose>> moved;
      for (const ViewId id : {static_cast<ViewId>(q / 3), static_cast<ViewId>(q - 2)}) {
        CameraPose p = selector.matrix().keyframe(id).pose;
        p.position.x() += 0.01;
        moved.emplace_back(id, p);
      }
      selector.correctPoses(moved);
    }
    if (q % 9 == 0) {
      const std::vector<uint8_t> r = encodeJournalRecord(5, index++, tracker.capture(selector));
      journal.insert(journal.end(), r.begin(), r.end());
    }
  }
  const std::vector<uint8_t> r = encodeJournalRecord(5, index++, tracker.capture(selector));
  journal.insert(journal.end(), r.begin(), r.end());
  const JournalReplay replay = replayJournal(state, journal.data(), journal.size());
  EXPECT_EQ(replay.error, "");
  EXPECT_EQ(replay.records, index);
  EXPECT_EQ(canonical(state), canonical(captureSession(selector)));
  EXPECT_GT(selector.matrix().table().finiteCount(), 700u);
}

// Compaction as the node's state keeper does it: the new base written atomically with a new id,
// then the journal emptied, then records of the new base appended. Every state the files can be
// in when the process is killed reads back complete.
TEST(StateJournal, AKillAtAnyStepOfACompactionLosesNothing) {
  const fs::path dir = fs::temp_directory_path() / ("state_journal_test_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string path = (dir / "state.vss").string();
  const std::string journal = journalPath(path);
  Journal j = makeJournal("depth", 1);
  writeStateFile(path, j.base);
  // Records appended one by one: after each, the session up to it.
  for (size_t q = 0; q < j.starts.size(); ++q) {
    const size_t end = q + 1 < j.starts.size() ? j.starts[q + 1] : j.bytes.size();
    appendToFile(journal, std::vector<uint8_t>(j.bytes.begin() + static_cast<long>(j.starts[q]),
                                               j.bytes.begin() + static_cast<long>(end)));
    EXPECT_EQ(canonical(readSession(path)), j.expected[q]) << "after record " << q;
  }
  const std::vector<uint8_t> complete = j.expected.back();
  // 1. The new base is being written: the old base and the whole journal are still there (the
  //    atomic write leaves at most a temporary file beside them).
  std::ofstream(path + ".tmp-partial", std::ios::binary) << "half a file";
  EXPECT_EQ(canonical(readSession(path)), complete);
  fs::remove(path + ".tmp-partial");
  // 2. The new base is in place, the journal not yet emptied: its records name the old base.
  SessionState compacted = readSession(path);
  compacted.base_id = 2;
  writeStateFile(path, compacted);
  JournalReplay replay;
  EXPECT_EQ(canonical(readSession(path, &replay)), complete);
  EXPECT_EQ(replay.stale, 4u);
  EXPECT_EQ(replay.error, "");
  // 3. The journal emptied.
  truncateFile(journal, 0);
  EXPECT_EQ(canonical(readSession(path)), complete);
  // 4. A record of the new base torn half way, then written whole.
  auto selector = makeSelector("depth");
  restoreSession(*selector, readSession(path));
  DeltaTracker tracker;
  tracker.markSaved(*selector);
  feed(*selector, "depth", 14, 18);
  const SessionDelta d = tracker.capture(*selector);
  const std::vector<uint8_t> record = encodeJournalRecord(2, 0, d);
  appendToFile(journal, std::vector<uint8_t>(record.begin(), record.begin() + record.size() / 2));
  EXPECT_EQ(canonical(readSession(path, &replay)), complete);
  EXPECT_NE(replay.error, "");
  truncateFile(journal, replay.good_bytes);  // what the keeper does before appending again
  appendToFile(journal, record);
  SessionState after = captureSession(*selector);
  after.statistics = d.rest.statistics;
  after.pair_sequence = d.rest.pair_sequence;
  EXPECT_EQ(canonical(readSession(path, &replay)), canonical(after));
  EXPECT_EQ(replay.records, 1u);
  EXPECT_EQ(replay.error, "");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace view_selection
