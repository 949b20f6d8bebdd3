#include "view_selection/core/keyframe_policy.h"

#include "view_selection/core/exceptions.h"

#include <gtest/gtest.h>
#include "support/layers.h"

namespace view_selection {
namespace {

CameraPose at(double x, double yaw_deg = 0.0) {
  CameraPose p;
  p.position = Eigen::Vector3d(x, 0.0, 0.0);
  p.orientation = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY());
  return p;
}

TEST(KeyframePolicy, EveryFrameAndEveryNth) {
  KeyframePolicy all({KeyframeMode::kEveryFrame, 10, 0.1, 10.0});
  for (int q = 0; q < 5; ++q) EXPECT_TRUE(all.offer(at(0.0)));
  KeyframePolicy nth({KeyframeMode::kEveryNth, 3, 0.1, 10.0});
  std::vector<int> kept;
  for (int q = 0; q < 10; ++q)
    if (nth.offer(at(0.0))) kept.push_back(q);
  EXPECT_EQ(kept, (std::vector<int>{0, 3, 6, 9}));
  nth.reset();
  EXPECT_TRUE(nth.offer(at(0.0)));
}

TEST(KeyframePolicy, MotionNeedsTranslationOrRotationSinceLastKeyframe) {
  KeyframePolicy p({KeyframeMode::kMotion, 1, 0.10, 10.0});
  ASSERT_TRUE(p.offer(at(0.0)));  // the first frame always
  p.keyframeAccepted(at(0.0));
  EXPECT_FALSE(p.offer(at(0.05)));
  EXPECT_FALSE(p.offer(at(0.05, 9.0)));
  EXPECT_TRUE(p.offer(at(0.05, 10.5)));  // rotation alone
  EXPECT_TRUE(p.offer(at(0.1001)));      // translation alone
  // Not confirmed: the reference stays at x = 0, so a frame 0.12 from it still qualifies
  // although it is only 0.02 from the last offered one.
  EXPECT_TRUE(p.offer(at(0.12)));
  p.keyframeAccepted(at(0.12));
  EXPECT_FALSE(p.offer(at(0.2)));
  EXPECT_TRUE(p.offer(at(0.23)));
}

TEST(KeyframePolicy, ExternalTakesTheCallersVerdict) {
  KeyframePolicy p({KeyframeMode::kExternal, 10, 0.1, 10.0});
  EXPECT_FALSE(p.offer(at(0.0)));  // no verdict: not even the first frame
  EXPECT_TRUE(p.offer(at(0.0), true));
  p.keyframeAccepted(at(0.0));
  EXPECT_TRUE(p.offer(at(0.0), true));          // no motion needed
  EXPECT_FALSE(p.offer(at(5.0, 90.0), false));  // nor enough
  EXPECT_EQ(keyframeModeFromString("external"), KeyframeMode::kExternal);
}

TEST(KeyframePolicy, ParsesAndValidates) {
  EXPECT_EQ(keyframeModeFromString("every_nth"), KeyframeMode::kEveryNth);
  EXPECT_EQ(toString(KeyframeMode::kMotion), "motion");
  EXPECT_THROW(keyframeModeFromString("sometimes"), InvalidArgument);
  EXPECT_THROW(KeyframePolicy({KeyframeMode::kEveryNth, 0, 0.1, 10.0}), InvalidArgument);
  EXPECT_THROW(KeyframePolicy({KeyframeMode::kMotion, 1, -0.1, 10.0}), InvalidArgument);
}

// A wall of 21 x 21 points `depth` in front of a camera at the origin looking along +z, all in
// `scale` units.
Eigen::Matrix3Xd wall(double scale, double depth = 2.0) {
  Eigen::Matrix3Xd points(3, 21 * 21);
  for (int y = 0; y < 21; ++y)
    for (int x = 0; x < 21; ++x)
      points.col(y * 21 + x) = scale * Eigen::Vector3d(-1.0 + 0.1 * x, -0.8 + 0.08 * y, depth);
  return points;
}

PinholeIntrinsics vga() { return {525.0, 525.0, 319.5, 239.5, 640, 480}; }

CameraPose scaled(CameraPose pose, double scale) {
  pose.position *= scale;
  return pose;
}

TEST(KeyframePolicy, ScaleFreeIsTheDefault) {
  EXPECT_EQ(KeyframePolicyConfig{}.mode, KeyframeMode::kScaleFree);
  EXPECT_EQ(keyframeModeFromString("scale_free"), KeyframeMode::kScaleFree);
  // motion says its unit wherever its rule is printed (select_views, the node's log).
  KeyframePolicyConfig motion;
  motion.mode = KeyframeMode::kMotion;
  EXPECT_NE(describeKeyframeRule(motion).find("0.1 scene units (metres if the poses are in metres)"),
            std::string::npos)
      << describeKeyframeRule(motion);
}

// Overlap and parallax are angles and ratios: the measure is the same in metres, millimetres and
// kilometres, and so is every decision.
TEST(KeyframePolicy, ScaleFreeMeasureIsTheSameInAnyUnit) {
  const std::vector<std::pair<CameraPose, std::string>> frames = {
      {at(0.0), "still"},          {at(0.1), "0.1 sideways"},  {at(0.2), "0.2 sideways"},
      {at(0.0, 8.0), "8 deg turn"}, {at(0.0, 15.0), "15 deg turn"}};
  std::vector<ViewChange> in_metres;
  for (const auto& [pose, what] : frames)
    in_metres.push_back(measureViewChange(wall(1.0), Eigen::Vector3d::Zero(), 525.0, pose, vga(),
                                          20.0, 1.6));
  EXPECT_EQ(in_metres[0].points, 441u);
  EXPECT_EQ(in_metres[0].matchable, 441u);
  EXPECT_DOUBLE_EQ(in_metres[0].overlap, 1.0);
  EXPECT_NEAR(in_metres[0].parallax_deg, 0.0, 1e-5);  // acos of a rounded 1
  // 0.1 sideways at 2 to 2.6 away: ~2.2-2.9 deg; the nearer points decide (90th percentile).
  EXPECT_NEAR(in_metres[1].parallax_deg, 2.8, 0.1);
  EXPECT_NEAR(in_metres[2].parallax_deg, 5.6, 0.2);
  EXPECT_GT(in_metres[3].overlap, 0.8);  // a turn moves points out of the image, no parallax
  EXPECT_LT(in_metres[4].overlap, 0.8);
  EXPECT_NEAR(in_metres[4].parallax_deg, 0.0, 1e-5);
  for (const double scale : {1000.0, 0.001}) {
    for (size_t q = 0; q < frames.size(); ++q) {
      const ViewChange c = measureViewChange(wall(scale), Eigen::Vector3d::Zero(), 525.0,
                                             scaled(frames[q].first, scale), vga(), 20.0, 1.6);
      EXPECT_EQ(c.visible, in_metres[q].visible) << frames[q].second << " x " << scale;
      EXPECT_EQ(c.matchable, in_metres[q].matchable) << frames[q].second << " x " << scale;
      EXPECT_NEAR(c.parallax_deg, in_metres[q].parallax_deg, 1e-9) << frames[q].second;
    }
  }
  // The decisions, at the defaults (overlap 0.8, parallax 5 deg), in every unit.
  for (const double scale : {1.0, 1000.0, 0.001}) {
    KeyframeReference reference;
    reference.intrinsics = vga();
    const Eigen::Matrix3Xd points = wall(scale);
    reference.points = &points;
    reference.max_parallax_deg = 20.0;
    reference.max_scale_ratio = 1.6;
    const PinholeIntrinsics k = vga();
    std::vector<bool> taken;
    for (const auto& [pose, what] : frames) {
      KeyframePolicy p;
      taken.push_back(p.offer(scaled(pose, scale), false, &reference, &k));
    }
    EXPECT_EQ(taken, (std::vector<bool>{false, false, true, false, true})) << scale;
  }
}

TEST(KeyframePolicy, ScaleFreeTakesFramesItCannotMeasure) {
  KeyframePolicy p;
  const PinholeIntrinsics k = vga();
  EXPECT_TRUE(p.offer(at(0.0), false, nullptr, &k));  // the first frame: no keyframe yet
  KeyframeReference reference;
  reference.intrinsics = vga();
  const Eigen::Matrix3Xd few = wall(1.0).leftCols(kMinReferencePoints - 1);
  reference.points = &few;
  EXPECT_TRUE(p.offer(at(0.0), false, &reference, &k));  // too few points to measure
  const Eigen::Matrix3Xd enough = wall(1.0).leftCols(kMinReferencePoints);
  reference.points = &enough;
  EXPECT_FALSE(p.offer(at(0.0), false, &reference, &k));
  ASSERT_TRUE(p.lastChange().has_value());
  EXPECT_EQ(p.lastChange()->points, static_cast<size_t>(kMinReferencePoints));
  // Behind the camera: nothing in view, a new keyframe.
  EXPECT_TRUE(p.offer(at(0.0, 180.0), false, &reference, &k));
  EXPECT_DOUBLE_EQ(p.lastChange()->overlap, 0.0);
}

}  // namespace
}  // namespace view_selection
