// The registration log beside the state file: a continued session gets back what the
// registration kept of exactly its own keyframes (same id and stamp, the newest record), whatever
// else the file holds (a crash before a save, a torn tail, an earlier session's records); a new
// session empties it; a log that cannot be written stops appending and says so.
#include "view_selection/session/registration_log.h"

#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/exceptions.h"
#include "view_selection/io/file_ops.h"

#include "support/layers.h"
#include "support/test_support.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <vector>

namespace view_selection {
namespace {

namespace fs = std::filesystem;

/// Keeps whatever bytes it is given, by keyframe id (what a real registration would keep of a
/// keyframe is its own affair; the log carries bytes). Refuses the bytes {0xBA, 0xD0}.
class BytesRegistration : public FrameRegistration {
 public:
  std::map<ViewId, std::vector<uint8_t>> kept;
  void keyframeAdded(ViewId, const Frame&) override {}
  std::optional<CameraPose> relativePose(const Frame&, ViewId) override { return std::nullopt; }
  std::vector<ViewId> alikeKeyframes(const Frame&, ViewId, size_t) override { return {}; }
  void clear() override { kept.clear(); }
  std::vector<uint8_t> keptBytes(ViewId id) const override {
    const auto it = kept.find(id);
    return it == kept.end() ? std::vector<uint8_t>() : it->second;
  }
  bool restoreKept(ViewId id, const std::vector<uint8_t>& bytes) override {
    if (bytes == std::vector<uint8_t>{0xBA, 0xD0}) return false;
    kept[id] = bytes;
    return true;
  }
};

/// Keyframes at the given stamps, each with a few points in front.
ErrorResistanceMatrix keyframesAt(const std::vector<double>& stamps) {
  ErrorResistanceMatrix m;
  for (size_t q = 0; q < stamps.size(); ++q) {
    Keyframe k;
    k.stamp = stamps[q];
    k.intrinsics = test::vgaIntrinsics();
    k.pose = test::lookAt(Eigen::Vector3d(0.1 * static_cast<double>(q), 0.0, 0.0),
                          Eigen::Vector3d(0.0, 0.0, 3.0));
    k.points = Eigen::Matrix3Xd(3, 3);
    k.points << -0.5, 0.0, 0.5, 0.0, 0.3, -0.3, 3.0, 3.2, 2.9;
    m.addKeyframe(k);
  }
  return m;
}

class RegistrationLogTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("registration_log_test_" + std::to_string(getpid()));
    fs::create_directories(dir_);
    state_ = (dir_ / "state.vss").string();
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
  std::string state_;
};

TEST_F(RegistrationLogTest, AContinuedSessionGetsBackItsOwnKeyframesOnly) {
  BytesRegistration before;
  RegistrationLog log(state_, before);
  EXPECT_EQ(log.path(), state_ + ".registration");
  EXPECT_EQ(log.startSession(), "");
  // Keyframe 3 keeps nothing and is not logged; keyframe 2's bytes will be refused.
  const std::vector<double> stamps{10.0, 10.5, 11.0, 11.5, 12.0};
  before.kept = {{0, {1, 2, 3}}, {1, {4}}, {2, {0xBA, 0xD0}}, {4, {9}}};
  for (ViewId id = 0; id < 5; ++id)
    EXPECT_EQ(log.keyframeAdded(id, stamps[static_cast<size_t>(id)]), "");
  EXPECT_EQ(readRegistrationLog(log.path()).size(), 4u) << "keyframe 3 kept nothing";
  // Keyframe 1 logged again, then once more at another stamp (a session continued from a state
  // file saved before it, whose next keyframe took id 1): the newest record with the continued
  // keyframe's stamp counts, not the newest record.
  before.kept[1] = {8, 8, 8};
  EXPECT_EQ(log.keyframeAdded(1, 10.5), "");
  before.kept[1] = {7, 7};
  EXPECT_EQ(log.keyframeAdded(1, 10.75), "");
  // A torn record at the end (a crash during an append).
  const std::vector<uint8_t> record = encodeRegistrationRecord({3, 11.5, {9, 9, 9, 9}});
  io::appendToFile(log.path(), std::vector<uint8_t>(record.begin(), record.begin() + 11));

  // The state file kept keyframes 0-3 only (4 came after its last save).
  const ErrorResistanceMatrix continued = keyframesAt({10.0, 10.5, 11.0, 11.5});
  BytesRegistration after;
  RegistrationLog again(state_, after);
  const RegistrationLog::Continued c = again.continueSession(continued);
  EXPECT_EQ(c.error, "");
  EXPECT_EQ(c.restored, 2u);
  EXPECT_EQ(c.dropped, 4u) << "keyframe 1 at 10.75 and its older record, 2 refused, 4 not kept";
  EXPECT_EQ(c.unread, 11u);
  const std::map<ViewId, std::vector<uint8_t>> expected{{0, {1, 2, 3}}, {1, {8, 8, 8}}};
  EXPECT_EQ(after.kept, expected);
  // The file holds exactly what was restored: read again, nothing is dropped.
  const std::vector<RegistrationRecord> left = readRegistrationLog(again.path());
  ASSERT_EQ(left.size(), 2u);
  EXPECT_EQ(left[1].id, 1);
  EXPECT_EQ(left[1].stamp, 10.5);
  BytesRegistration third;
  const RegistrationLog::Continued c2 = RegistrationLog(state_, third).continueSession(continued);
  EXPECT_EQ(c2.restored, 2u);
  EXPECT_EQ(c2.dropped + c2.unread, 0u);
  EXPECT_EQ(third.kept, expected);
  // Later keyframes are appended after them.
  after.kept[4] = {4, 4};
  EXPECT_EQ(again.keyframeAdded(4, 12.5), "");
  EXPECT_EQ(readRegistrationLog(again.path()).size(), 3u);

  // A new session empties it.
  EXPECT_EQ(again.startSession(), "");
  EXPECT_TRUE(readRegistrationLog(again.path()).empty());
  EXPECT_EQ(fs::file_size(again.path()), 0u);
}

TEST_F(RegistrationLogTest, ACorruptRecordEndsWhatIsRead) {
  std::vector<uint8_t> bytes;
  for (int id = 0; id < 3; ++id) {
    const std::vector<uint8_t> r = encodeRegistrationRecord({id, 1.0 + id, {1, 2, 3}});
    bytes.insert(bytes.end(), r.begin(), r.end());
  }
  size_t unread = 1;
  EXPECT_EQ(decodeRegistrationRecords(bytes.data(), bytes.size(), &unread).size(), 3u);
  EXPECT_EQ(unread, 0u);
  const size_t one = bytes.size() / 3;
  bytes[one + 10] ^= 0x40;  // in the second record's payload: its CRC no longer matches
  EXPECT_EQ(decodeRegistrationRecords(bytes.data(), bytes.size(), &unread).size(), 1u);
  EXPECT_EQ(unread, 2 * one);
  bytes[one + 10] ^= 0x40;
  bytes[one] = 'X';  // not a record's tag
  EXPECT_EQ(decodeRegistrationRecords(bytes.data(), bytes.size(), &unread).size(), 1u);
  // A missing file has no records; one that cannot be read is an error.
  EXPECT_TRUE(readRegistrationLog(state_ + ".none").empty());
  fs::create_directories(dir_ / "a_folder");
  EXPECT_THROW(readRegistrationLog((dir_ / "a_folder").string()), IoError);
}

TEST_F(RegistrationLogTest, ALogThatCannotBeWrittenStopsAndSaysWhy) {
  BytesRegistration r;
  r.kept = {{0, {1}}, {1, {2}}};
  // Nothing kept without a state file.
  RegistrationLog off("", r);
  EXPECT_EQ(off.startSession(), "");
  EXPECT_EQ(off.keyframeAdded(0, 1.0), "");
  EXPECT_EQ(off.continueSession(keyframesAt({1.0})).restored, 0u);
  EXPECT_TRUE(r.kept.count(0));
  // The state file's folder is made when missing (the state keeper makes it at its first save,
  // later than the first keyframe).
  RegistrationLog fresh((dir_ / "new" / "state.vss").string(), r);
  EXPECT_EQ(fresh.startSession(), "");
  EXPECT_EQ(fresh.keyframeAdded(0, 1.0), "");
  EXPECT_EQ(readRegistrationLog(fresh.path()).size(), 1u);
  // Under a file where its folder should be: it cannot be made, says so, and this session
  // appends nothing, even once it could.
  const fs::path blocked = dir_ / "blocked";
  std::ofstream(blocked.string()) << "a file";
  RegistrationLog gone((blocked / "state.vss").string(), r);
  EXPECT_NE(gone.startSession(), "");
  fs::remove(blocked);
  fs::create_directories(blocked);
  EXPECT_EQ(gone.keyframeAdded(0, 1.0), "");
  EXPECT_FALSE(fs::exists(gone.path()));
  // A new session that can write appends again.
  EXPECT_EQ(gone.startSession(), "");
  EXPECT_EQ(gone.keyframeAdded(1, 2.0), "");
  EXPECT_EQ(readRegistrationLog(gone.path()).size(), 1u);
  // The folder gone mid-session: the append fails and says so, later ones are not tried.
  fs::remove_all(blocked);
  const std::string error = gone.keyframeAdded(0, 3.0);
  EXPECT_NE(error.find("cannot append to the registration log"), std::string::npos) << error;
  fs::create_directories(blocked);
  EXPECT_EQ(gone.keyframeAdded(1, 4.0), "") << "nothing more this session";
  EXPECT_FALSE(fs::exists(gone.path()));
}

}  // namespace
}  // namespace view_selection
