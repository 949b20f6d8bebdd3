// The scale_free policy's revisit rule (issue 34): walking round the same place again adds no
// keyframe where an earlier keyframe already has the view; a pass that sees the place anew (from
// nearer, or looking the other way) does.
#include "view_selection/core/view_selector.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/points/depth_point_source.h"

#include "support/box_depth.h"
#include "support/layers.h"
#include "support/test_support.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

namespace view_selection {
namespace {

const Eigen::Vector3d kRoom(3.0, 1.5, 2.5);  // half extents [m]

PinholeIntrinsics qvga() {
  PinholeIntrinsics k = test::vgaIntrinsics();
  k.fx /= 2.0;
  k.fy /= 2.0;
  k.cx = (k.cx + 0.5) / 2.0 - 0.5;
  k.cy = (k.cy + 0.5) / 2.0 - 0.5;
  k.width /= 2;
  k.height /= 2;
  return k;
}

/// One round of a circle of `radius` [m] in the room's middle plane, 0.03 rad a frame from
/// `phase`, looking outwards (at the nearer walls) or inwards (across the room). Returns the
/// keyframes it added; frames the policy does not want get no depth (as the node skips it).
struct Walk {
  ViewSelector selector{ViewSelectorConfig{}, std::make_unique<DepthPointSource>()};
  double stamp = 0.0;
  std::vector<cv::Mat> keep;  // depth the frames view

  size_t round(double radius, double phase, bool outwards) {
    const size_t before = selector.matrix().size();
    for (int q = 0; q < 210; ++q) {
      const double angle = phase + 0.03 * q;
      const Eigen::Vector3d eye(radius * std::cos(angle), 0.0, radius * std::sin(angle));
      Frame f;
      f.stamp = stamp += 1.0 / 30.0;
      f.image_name = std::to_string(f.stamp) + ".png";
      f.intrinsics = qvga();
      f.pose = test::lookAt(eye, outwards ? Eigen::Vector3d(3.0 * eye) : Eigen::Vector3d(-eye));
      const bool wanted = selector.wantsFrame(f);
      if (wanted) {
        keep.push_back(test::renderBoxDepth(f.intrinsics, f.pose, kRoom));
        f.depth = depthImageOf(keep.back());
      }
      const FrameResult r = selector.addFrame(f);
      EXPECT_EQ(r.outcome == FrameOutcome::kKeyframe, wanted) << angle;
    }
    return selector.matrix().size() - before;
  }
};

TEST(RevisitKeyframes, ThreePassesKeepTheFirstPassesKeyframes) {
  Walk walk;
  const size_t first = walk.round(1.0, 0.0, true);
  EXPECT_GE(first, 10u);  // a round of 6.3 rad outwards needs a keyframe every few tenths
  // Again, half a frame's step later (no frame of it is one of the first), then a little wider:
  // the same views, so no keyframe. Without the rule each pass adds about as many as the first,
  // since the frame is measured against the last keyframe only (a whole round ago by then).
  EXPECT_EQ(walk.round(1.0, 0.015, true), 0u);
  EXPECT_EQ(walk.round(1.02, 0.0, true), 0u);
  EXPECT_GT(walk.selector.revisitsSkipped(), 0u);
  const size_t after_three = walk.selector.matrix().size();
  EXPECT_EQ(after_three, first);

  // Nearer the walls (from 2 m to 1.2 m on the long axis: the walls' detail in a narrower
  // footprint) is new.
  EXPECT_GE(walk.round(1.8, 0.0, true), first / 2);
  // Looking the other way (across the room, at walls seen from twice as far before) is new.
  const size_t inwards = walk.round(1.0, 0.0, false);
  EXPECT_GE(inwards, 5u);
  // ... and once seen, a second inward pass adds nothing.
  EXPECT_EQ(walk.round(1.0, 0.015, false), 0u);
}

// A session continued from its saved state finds the earlier pass's keyframes as the
// uninterrupted one does (the rule reads only the keyframes; restore indexes them again).
TEST(RevisitKeyframes, RestoredSessionDecidesAsTheUninterruptedOne) {
  Walk whole, continued;
  whole.round(1.0, 0.0, true);
  continued.selector.restore(whole.selector.state());
  continued.stamp = whole.stamp;
  for (Walk* w : {&whole, &continued}) {
    EXPECT_EQ(w->round(1.0, 0.015, true), 0u);
    EXPECT_GT(w->round(1.8, 0.0, true), 0u);
  }
  EXPECT_GT(continued.selector.revisitsSkipped(), 0u);
  ASSERT_EQ(continued.selector.matrix().size(), whole.selector.matrix().size());
  for (size_t i = 0; i < whole.selector.matrix().size(); ++i)
    EXPECT_EQ(continued.selector.matrix().keyframe(static_cast<ViewId>(i)).stamp,
              whole.selector.matrix().keyframe(static_cast<ViewId>(i)).stamp);
  EXPECT_EQ(continued.selector.select().pairs, whole.selector.select().pairs);
}

// The rule is the scale_free policy's alone: every_nth (and every_frame, motion, external)
// keep what they kept.
TEST(RevisitKeyframes, OtherPoliciesKeepEveryFrameTheyChoose) {
  Walk walk;
  ViewSelectorConfig config;
  config.keyframes.mode = KeyframeMode::kEveryNth;
  config.keyframes.every_n = 15;
  walk.selector = ViewSelector(config, std::make_unique<DepthPointSource>());
  EXPECT_EQ(walk.round(1.0, 0.0, true), 14u);
  EXPECT_EQ(walk.round(1.0, 0.015, true), 14u);
  EXPECT_EQ(walk.selector.revisitsSkipped(), 0u);
}

}  // namespace
}  // namespace view_selection
