// The state keeper and the worker's persistence hand-off (~state_file), without a master: what
// was handed to the keeper's thread is on disk once the keeper is gone, even when it was still
// waiting behind a long write (issue 30: a clean shutdown lost the last autosave), and a save
// handed over with a callback reports its result.
#include "view_selection/core/view_selector.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/node_config.h"
#include "view_selection/ros/session_handoff.h"
#include "view_selection/ros/state_keeper.h"
#include "view_selection/session/capture.h"
#include "view_selection/session/state_file.h"

#include "support/box_depth.h"
#include "support/test_support.h"

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include <unistd.h>

#include <filesystem>
#include <future>
#include <memory>
#include <string>
#include <thread>

namespace view_selection {
namespace {

namespace fs = std::filesystem;
using ros_node::InputStatistics;
using ros_node::NodeConfig;
using ros_node::SaveResult;
using ros_node::SessionHandoff;
using ros_node::StateKeeper;

/// Frame q of a walk inside a box room, with exact depth: every frame a keyframe (every_frame).
core::Frame boxFrame(int q) {
  core::Frame f;
  f.stamp = 100.0 + 0.1 * q;
  f.image_name = "rgb/" + std::to_string(q) + ".png";
  f.intrinsics = test::vgaIntrinsics(150.0);
  f.intrinsics.width = 160;
  f.intrinsics.height = 120;
  f.intrinsics.cx = 79.5;
  f.intrinsics.cy = 59.5;
  f.pose = test::lookAt(Eigen::Vector3d(-1.0 + 0.02 * q, 0.1, -1.5), Eigen::Vector3d(0.0, 0.0, 3.0));
  f.image = images::colourImageOf(cv::Mat(120, 160, CV_8UC3, cv::Scalar(90, 120, 150)));
  f.depth = images::depthImageOf(
      test::renderBoxDepth(f.intrinsics, f.pose, Eigen::Vector3d(3.0, 2.0, 3.0)));
  return f;
}

class StateKeeperTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("view_selection_state_keeper_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    config_.state_file = (dir_ / "session.state").string();
    config_.autosave_keyframes = 1;
    config_.selector.keyframes.mode = core::KeyframeMode::kEveryFrame;
    config_.point_params.depth.grid = 32;  // many points a keyframe: a whole save takes a while
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::unique_ptr<core::ViewSelector> selector() const {
    return std::make_unique<core::ViewSelector>(
        config_.selector,
        points::makePointSource("depth", config_.point_params, config_.selector.matrix.occlusion));
  }

  fs::path dir_;
  NodeConfig config_;
  InputStatistics statistics_;
};

TEST_F(StateKeeperTest, WhatWaitsForTheKeepersThreadIsOnDiskOnceItIsGone) {
  auto s = selector();
  constexpr int kFrames = 40;
  {
    StateKeeper keeper(config_, statistics_, "test");
    SessionHandoff handoff(config_, keeper, statistics_, nullptr);
    for (int q = 0; q < kFrames; ++q)
      ASSERT_EQ(s->addFrame(boxFrame(q)).outcome, core::FrameOutcome::kKeyframe);
    keeper.saveLater(handoff.captureWhole(*s));  // the base, with the journal's id
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (keeper.wantsFull() && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    ASSERT_FALSE(keeper.wantsFull()) << "the base was not written within 30 s";
    ASSERT_EQ(s->addFrame(boxFrame(kFrames)).outcome, core::FrameOutcome::kKeyframe);
    // The keeper's thread busy with a long write (a time jump's session, whole), and the
    // autosave of the last keyframe handed over behind it: it clears "changed since the save",
    // so the worker's shutdown save has nothing to add. Then the keeper goes at once, as on
    // shutdown.
    keeper.saveAside({0, session::captureSession(*s)});
    handoff.keyframeInserted(*s);  // ~autosave_keyframes 1: a journal record
  }
  session::JournalReplay replay;
  const session::SessionState saved = session::readSession(config_.state_file, &replay);
  EXPECT_EQ(saved.selector.keyframes.size(), static_cast<size_t>(kFrames + 1))
      << "the last autosave, still waiting when the keeper stopped, was lost (" << replay.records
      << " journal records read)";
  EXPECT_EQ(replay.records, 1u);
  EXPECT_TRUE(fs::exists(config_.state_file + StateKeeper::kPreviousSuffix));
}

TEST_F(StateKeeperTest, ASaveHandedOverReportsItsResult) {
  auto s = selector();
  for (int q = 0; q < 3; ++q) s->addFrame(boxFrame(q));
  StateKeeper keeper(config_, statistics_, "test");
  SessionHandoff handoff(config_, keeper, statistics_, nullptr);
  std::promise<SaveResult> done;
  keeper.saveLater(handoff.captureWhole(*s), [&](const SaveResult& r) { done.set_value(r); });
  std::future<SaveResult> result = done.get_future();
  ASSERT_EQ(result.wait_for(std::chrono::seconds(30)), std::future_status::ready);
  const SaveResult r = result.get();
  EXPECT_TRUE(r.ok) << r.message;
  EXPECT_NE(r.message.find("wrote 3 keyframes"), std::string::npos) << r.message;
  EXPECT_TRUE(fs::exists(config_.state_file));

  // Saving off: the callback says so at once.
  NodeConfig off = config_;
  off.state_file.clear();
  StateKeeper none(off, statistics_, "test");
  bool called = false;
  none.saveLater({}, [&](const SaveResult& r) {
    called = true;
    EXPECT_FALSE(r.ok);
    EXPECT_NE(r.message.find("state_file"), std::string::npos) << r.message;
  });
  EXPECT_TRUE(called);
}

}  // namespace
}  // namespace view_selection
