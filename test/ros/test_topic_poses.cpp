// The topic pose sources' step from received body poses to the pose at an image stamp (no
// master): a pose at the stamp as it is, else the two around it interpolated, never the nearest.
#include "view_selection/ros/pose_provider.h"

#include <gtest/gtest.h>

namespace view_selection::ros_node {
namespace {

// Whole seconds and nanoseconds: a double near 1.3e9 s resolves only 0.24 us.
ros::Time stampAt(double t) { return ros::Time(1305031000, static_cast<uint32_t>(t * 1e9 + 0.5)); }

ReceivedPose at(double t, double x, double yaw, const std::string& frame = "world") {
  ReceivedPose p;
  p.stamp = stampAt(t);
  p.frame = frame;
  p.child_frame = "body";
  p.pose.position = Eigen::Vector3d(x, 0.0, 0.0);
  p.pose.orientation = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ());
  return p;
}

TEST(TopicPoses, AStampBetweenTwoPosesIsInterpolatedNotTheNearest) {
  const std::deque<ReceivedPose> poses{at(0.00, 0.0, 0.0), at(0.01, 1.0, 0.2), at(0.02, 3.0, 0.4)};
  PoseLookup out;
  const auto p = TopicPoseProvider::bodyPoseAt(poses, stampAt(0.0125), 0.02, out);
  ASSERT_TRUE(p) << out.message;
  EXPECT_NEAR(p->pose.position.x(), 1.5, 1e-9);  // a quarter of the way from 1 to 3
  EXPECT_NEAR(p->pose.orientation.angularDistance(
                  Eigen::Quaterniond(Eigen::AngleAxisd(0.25, Eigen::Vector3d::UnitZ()))),
              0.0, 1e-9);
  EXPECT_EQ(p->child_frame, "body");
}

TEST(TopicPoses, APoseAtTheStampIsTakenAsItIs) {
  ReceivedPose odd = at(0.01, 1.0, 0.2);
  odd.pose.orientation.coeffs() *= 1.01;  // not unit length: not normalised here
  const std::deque<ReceivedPose> poses{at(0.0, 0.0, 0.0), odd, at(0.02, 3.0, 0.4)};
  PoseLookup out;
  const auto p = TopicPoseProvider::bodyPoseAt(poses, odd.stamp, 0.02, out);
  ASSERT_TRUE(p);
  EXPECT_EQ(p->pose.position, odd.pose.position);
  EXPECT_EQ(p->pose.orientation.coeffs(), odd.pose.orientation.coeffs());
}

TEST(TopicPoses, NoPoseWhenOneSideIsMissingOrTooFar) {
  const std::deque<ReceivedPose> poses{at(0.0, 0.0, 0.0), at(0.1, 1.0, 0.0)};
  PoseLookup out;
  // 0.05 from both: farther than 0.02 allows, although 0.1 apart poses exist on both sides.
  EXPECT_FALSE(TopicPoseProvider::bodyPoseAt(poses, stampAt(0.05), 0.02, out));
  EXPECT_EQ(out.reason, "no_pose");
  EXPECT_NE(out.message.find("~pose_max_time_difference"), std::string::npos) << out.message;
  // After the last pose: no extrapolation, whatever the distance.
  PoseLookup after;
  EXPECT_FALSE(TopicPoseProvider::bodyPoseAt(poses, stampAt(0.101), 0.02, after));
  EXPECT_EQ(after.reason, "no_pose");
  PoseLookup wide;
  EXPECT_TRUE(TopicPoseProvider::bodyPoseAt(poses, stampAt(0.05), 0.06, wide));
}

TEST(TopicPoses, PosesAroundTheStampInDifferentFramesAreABadPose) {
  const std::deque<ReceivedPose> poses{at(0.0, 0.0, 0.0, "world"), at(0.01, 1.0, 0.0, "odom")};
  PoseLookup out;
  EXPECT_FALSE(TopicPoseProvider::bodyPoseAt(poses, stampAt(0.005), 0.02, out));
  EXPECT_EQ(out.reason, "bad_pose");
}

// A restarted SLAM system or a bag played again: poses more than the threshold before the newest
// are another timeline; the old poses go, so none is interpolated with a new one.
TEST(TopicPoses, APoseFarBeforeTheNewestStartsANewTimeline) {
  std::deque<ReceivedPose> poses;
  for (int q = 0; q <= 30; ++q)
    EXPECT_FALSE(TopicPoseProvider::addPose(poses, at(0.1 * q, 0.1 * q, 0.0), 1.0));
  ASSERT_EQ(poses.size(), 31u);
  // Out of order by less than the threshold: kept in order with the others.
  EXPECT_FALSE(TopicPoseProvider::addPose(poses, at(2.05, 9.0, 0.0), 1.0));
  EXPECT_EQ(poses.size(), 32u);
  // Back 1.5 s: the old timeline had poses on both sides of 1.55 s, the new one has one.
  EXPECT_TRUE(TopicPoseProvider::addPose(poses, at(1.5, 5.0, 0.0), 1.0));
  ASSERT_EQ(poses.size(), 1u);
  PoseLookup out;
  EXPECT_FALSE(TopicPoseProvider::bodyPoseAt(poses, stampAt(1.55), 0.12, out));
  EXPECT_FALSE(TopicPoseProvider::addPose(poses, at(1.6, 6.0, 0.0), 1.0));
  const auto p = TopicPoseProvider::bodyPoseAt(poses, stampAt(1.55), 0.12, out);
  ASSERT_TRUE(p) << out.message;
  EXPECT_NEAR(p->pose.position.x(), 5.5, 1e-9);
  // Threshold 0: never a new timeline.
  EXPECT_FALSE(TopicPoseProvider::addPose(poses, at(0.0, 0.0, 0.0), 0.0));
  EXPECT_EQ(poses.size(), 3u);
}

}  // namespace
}  // namespace view_selection::ros_node
