#include "view_selection/core/pose_correction.h"

#include <gtest/gtest.h>

namespace view_selection::core {
namespace {

TimedPose at(double t, double x, double yaw_deg = 0.0) {
  TimedPose p;
  p.stamp = t;
  p.pose.position = Eigen::Vector3d(x, 0.0, 0.0);
  p.pose.orientation = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY());
  return p;
}

TEST(PoseCorrection, KeyframesTakeTheTrajectoryPoseAtTheirStampWhenTheyMovedEnough) {
  const std::vector<TimedPose> keyframes{at(1.0, 0.0), at(2.0, 1.0), at(3.0, 2.0), at(4.0, 3.0)};
  const std::vector<TimedPose> path{at(0.9995, 0.0001),    // keyframe 0: moved less than 2 mm
                                    at(2.004, 1.05),       // keyframe 1: 5 cm, 4 ms off
                                    at(3.05, 2.5),         // keyframe 2: 50 ms off, not matched
                                    at(3.999, 3.0, 0.5)};  // keyframe 3: turned 0.5 degrees
  const auto moves = matchCorrections(keyframes, path, PoseCorrectionConfig{});
  ASSERT_EQ(moves.size(), 2u);
  EXPECT_EQ(moves[0].first, 1);
  EXPECT_DOUBLE_EQ(moves[0].second.position.x(), 1.05);
  EXPECT_EQ(moves[1].first, 3);
  EXPECT_NEAR(rotationDegrees(moves[1].second, keyframes[3].pose), 0.5, 1e-9);
  // A larger tolerance reaches keyframe 2; smaller thresholds take keyframe 0 too.
  PoseCorrectionConfig loose;
  loose.stamp_tolerance = 0.06;
  loose.min_translation = 1e-5;
  EXPECT_EQ(matchCorrections(keyframes, path, loose).size(), 4u);
  EXPECT_TRUE(matchCorrections(keyframes, {}, loose).empty());
}

TEST(PoseCorrection, TheNearerOfTwoTrajectoryPosesWins) {
  const std::vector<TimedPose> keyframes{at(1.0, 0.0)};
  const auto moves =
      matchCorrections(keyframes, {at(0.996, 0.3), at(1.003, 0.2)}, PoseCorrectionConfig{});
  ASSERT_EQ(moves.size(), 1u);
  EXPECT_DOUBLE_EQ(moves[0].second.position.x(), 0.2);
}

}  // namespace
}  // namespace view_selection::core
