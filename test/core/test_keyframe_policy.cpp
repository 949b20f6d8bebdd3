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

}  // namespace
}  // namespace view_selection
