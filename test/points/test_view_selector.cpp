// The ROS-free pipeline shared by the node and select_views: validation, stamps, policy,
// points, incremental matrix, and that bad frames change nothing.
#include "view_selection/core/view_selector.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/params_json.h"
#include "view_selection/points/depth_point_source.h"
#include "view_selection/images/image_conversion.h"

#include "support/box_depth.h"
#include "support/layers.h"
#include "support/test_support.h"

#include <gtest/gtest.h>

#include <memory>

namespace view_selection {
namespace {

using test::lookAt;
using test::vgaIntrinsics;

const Eigen::Vector3d kRoom(3.0, 1.5, 2.5);

Frame frameAt(double stamp, double angle) {
  Frame f;
  f.stamp = stamp;
  f.image_name = std::to_string(stamp) + ".png";
  f.intrinsics = vgaIntrinsics();
  // Walk on a circle of 1 m radius, looking outwards at the walls.
  const Eigen::Vector3d eye(std::cos(angle), 0.0, std::sin(angle));
  f.pose = lookAt(eye, 3.0 * eye);
  f.depth = depthImageOf(test::renderBoxDepth(f.intrinsics, f.pose, kRoom));
  return f;
}

std::unique_ptr<PointSource> depthSource() { return std::make_unique<DepthPointSource>(); }

ViewSelectorConfig everyFrame() {
  ViewSelectorConfig c;
  c.keyframes.mode = KeyframeMode::kEveryFrame;
  return c;
}

TEST(ViewSelector, FramesBecomeKeyframesAndSelectionCoversThem) {
  ViewSelector selector(everyFrame(), depthSource());
  for (int q = 0; q < 12; ++q) {
    const FrameResult r = selector.addFrame(frameAt(q, q * 0.15));
    ASSERT_EQ(r.outcome, FrameOutcome::kKeyframe);
    EXPECT_EQ(r.id, q);
    EXPECT_EQ(r.points, 256u);
  }
  EXPECT_EQ(selector.matrix().size(), 12u);
  const Selection s = selector.select();
  EXPECT_GE(s.start_view, 0);
  EXPECT_TRUE(s.isolated.empty());
  size_t non_empty = 0;
  for (const auto& set : s.next_views) non_empty += set.empty() ? 0 : 1;
  EXPECT_EQ(non_empty, 12u);
  // Neighbouring views overlap, so most of each row is finite; the far side of the circle not.
  EXPECT_GT(selector.matrix().table().finiteCount(), 12u * 3);
  EXPECT_LT(selector.matrix().table().finiteCount(), 12u * 11);
  const auto params = toJson(selector.params());
  EXPECT_EQ(params.at("k"), 5);
  EXPECT_EQ(params.at("completion"), toString(SelectionConfig{}.completion));
  EXPECT_EQ(params.at("point_source"), "depth");
  EXPECT_EQ(params.at("keyframe_policy"), "every_frame");
}

TEST(ViewSelector, RejectsBadFramesWithoutChangingState) {
  ViewSelector selector(everyFrame(), depthSource());
  selector.addFrame(frameAt(1.0, 0.0));
  selector.addFrame(frameAt(2.0, 0.1));
  const auto before = selector.matrix().table();

  Frame dup = frameAt(2.0, 0.2);
  EXPECT_THROW(selector.addFrame(dup), InvalidInput);                // duplicate stamp
  EXPECT_THROW(selector.addFrame(frameAt(1.5, 0.2)), InvalidInput);  // out of order
  Frame nan_pose = frameAt(3.0, 0.2);
  nan_pose.pose.orientation.x() = std::nan("");
  EXPECT_THROW(selector.addFrame(nan_pose), InvalidInput);
  Frame zero_focal = frameAt(3.0, 0.2);
  zero_focal.intrinsics.fx = 0.0;
  EXPECT_THROW(selector.addFrame(zero_focal), InvalidInput);
  Frame wrong_depth = frameAt(3.0, 0.2);
  const cv::Mat millimetres(480, 640, CV_16UC1, cv::Scalar(1000));
  EXPECT_THROW(depthImageOf(millimetres), InvalidInput);  // not metres: no view of it is made
  const cv::Mat two_channels(480, 640, CV_32FC2, cv::Scalar(1.0, 1.0));
  wrong_depth.depth = depthImageOf(cv::Mat(480, 640, CV_32FC1, cv::Scalar(1.0)));
  wrong_depth.depth.data = two_channels.data;
  wrong_depth.depth.channels = 2;
  wrong_depth.depth.step = two_channels.step[0];
  EXPECT_THROW(selector.addFrame(wrong_depth), InvalidInput);
  Frame no_depth = frameAt(3.0, 0.2);
  no_depth.depth = {};
  EXPECT_THROW(selector.addFrame(no_depth), InvalidInput);  // the depth source needs depth
  Frame wrong_size = frameAt(3.0, 0.2);
  wrong_size.image = colourImageOf(cv::Mat(100, 100, CV_8UC3));
  EXPECT_THROW(selector.addFrame(wrong_size), InvalidInput);

  EXPECT_EQ(selector.matrix().size(), 2u);
  EXPECT_EQ(selector.matrix().table(), before);
  // A good frame after all that is accepted with the next id.
  EXPECT_EQ(selector.addFrame(frameAt(3.0, 0.2)).id, 2);
  selector.reset();
  EXPECT_EQ(selector.matrix().size(), 0u);
  EXPECT_EQ(selector.addFrame(frameAt(0.5, 0.0)).id, 0);  // stamps start afresh after reset
}

TEST(ViewSelector, PolicySkipsFramesAndSameFramesGiveSameMatrix) {
  ViewSelectorConfig config;
  config.keyframes = {KeyframeMode::kMotion, 1, 0.10, 10.0};
  ViewSelector a(config, depthSource()), b(config, depthSource());
  int keyframes = 0;
  for (int q = 0; q < 40; ++q) {
    // 0.05 rad per frame on a 1 m circle: 2 frames apart is a 0.09996 m chord (and 5.7 deg),
    // 3 frames 0.1499 m, so translation makes every 3rd frame a keyframe: 0, 3, ..., 39.
    const Frame f = frameAt(q, q * 0.05);
    const FrameResult r = a.addFrame(f);
    keyframes += r.outcome == FrameOutcome::kKeyframe ? 1 : 0;
    b.addFrame(f);
  }
  EXPECT_EQ(keyframes, 14);
  EXPECT_EQ(a.matrix().table(), b.matrix().table());
  EXPECT_EQ(a.select().pairs, b.select().pairs);
}

}  // namespace
}  // namespace view_selection

namespace view_selection {
namespace {

TEST(ViewSelector, WantsFrameAsksThePolicyWithoutChangingIt) {
  ViewSelectorConfig config;
  config.keyframes = {KeyframeMode::kEveryNth, 3, 0.1, 10.0};
  ViewSelector selector(config, depthSource());
  for (int q = 0; q < 7; ++q) {
    Frame f = frameAt(q, q * 0.05);
    const bool wanted = selector.wantsFrame(f);
    EXPECT_EQ(wanted, q % 3 == 0) << q;
    EXPECT_EQ(selector.wantsFrame(f), wanted);  // asking twice changes nothing
    if (!wanted) f.depth = {};                       // skipped frames need no depth
    EXPECT_EQ(selector.addFrame(f).outcome == FrameOutcome::kKeyframe, wanted);
  }
  EXPECT_EQ(selector.matrix().size(), 3u);
}

// A restored selector acts and reports as one built with the same config: with the paper's
// gate, the gate's values in force whatever the saved config says (as the constructor does).
TEST(ViewSelector, RestoreAppliesTheGateAsTheConstructorDoes) {
  ViewSelectorConfig config = everyFrame();
  config.matrix.gate = Gate::kPaper;
  config.matrix.min_covisible_ratio = 0.4;
  config.matrix.max_parallax_deg = 15.0;
  ViewSelector built(config, depthSource());
  for (int q = 0; q < 4; ++q) built.addFrame(frameAt(q, q * 0.15));
  ViewSelectorState state = built.state();
  state.config = config;  // as requested, not as in force
  ViewSelector restored(everyFrame(), depthSource());
  restored.restore(state);
  EXPECT_EQ(restored.config().matrix.min_covisible_ratio, 0.1);
  EXPECT_EQ(restored.config().matrix.max_parallax_deg, 0.0);
  EXPECT_EQ(toJson(restored.params()), toJson(built.params()));
}

}  // namespace
}  // namespace view_selection
