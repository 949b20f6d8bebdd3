#include "view_selection/core/pose_interpolation.h"

#include "view_selection/core/exceptions.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace view_selection::core {
namespace {

CameraPose pose(const Eigen::Vector3d& p, double angle, const Eigen::Vector3d& axis) {
  CameraPose out;
  out.position = p;
  out.orientation = Eigen::AngleAxisd(angle, axis.normalized());
  return out;
}

double angleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return a.angularDistance(b);
}

TEST(PoseInterpolation, TranslationIsLinearRotationIsSlerp) {
  const Eigen::Vector3d axis(0.3, -1.0, 0.2);
  const TimedPose a{10.0, pose({0.0, 1.0, 2.0}, 0.2, axis)};
  const TimedPose b{10.5, pose({1.0, -1.0, 4.0}, 1.0, axis)};
  for (double s : {0.0, 0.1, 0.25, 0.5, 0.9, 1.0}) {
    const CameraPose p = interpolatePose(a, b, 10.0 + 0.5 * s);
    EXPECT_NEAR((p.position - Eigen::Vector3d(s, 1.0 - 2.0 * s, 2.0 + 2.0 * s)).norm(), 0.0, 1e-12)
        << s;
    // Same axis: the angle grows linearly from 0.2 to 1.0.
    const Eigen::Quaterniond expected(Eigen::AngleAxisd(0.2 + 0.8 * s, axis.normalized()));
    EXPECT_NEAR(angleBetween(p.orientation, expected), 0.0, 1e-9) << s;
    EXPECT_NEAR(p.orientation.norm(), 1.0, 1e-12);
  }
}

TEST(PoseInterpolation, TakesTheShorterArcWhateverTheQuaternionSign) {
  const Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  TimedPose a{0.0, pose(Eigen::Vector3d::Zero(), 0.1, axis)};
  TimedPose b{1.0, pose(Eigen::Vector3d::Zero(), 0.3, axis)};
  b.pose.orientation.coeffs() *= -1.0;  // the same rotation, the other hemisphere
  const CameraPose mid = interpolatePose(a, b, 0.5);
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(0.2, axis));
  EXPECT_NEAR(angleBetween(mid.orientation, expected), 0.0, 1e-9);
}

TEST(PoseInterpolation, RandomPairsStayOnTheGeodesic) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int q = 0; q < 200; ++q) {
    TimedPose a{1.0, pose({u(rng), u(rng), u(rng)}, 3.0 * u(rng), {u(rng), u(rng), u(rng) + 2.0})};
    TimedPose b{1.2, pose({u(rng), u(rng), u(rng)}, 3.0 * u(rng), {u(rng) + 2.0, u(rng), u(rng)})};
    const double s = 0.5 * (u(rng) + 1.0);
    const CameraPose p = interpolatePose(a, b, 1.0 + 0.2 * s);
    const double whole = angleBetween(a.pose.orientation, b.pose.orientation);
    EXPECT_NEAR(angleBetween(a.pose.orientation, p.orientation), s * whole, 1e-9);
    EXPECT_NEAR(angleBetween(p.orientation, b.pose.orientation), (1.0 - s) * whole, 1e-9);
    EXPECT_LE(whole, M_PI + 1e-12);
  }
}

TEST(PoseInterpolation, EqualStampsGiveTheFirstPose) {
  const TimedPose a{5.0, pose({1.0, 2.0, 3.0}, 0.4, Eigen::Vector3d::UnitX())};
  const TimedPose b{5.0, pose({9.0, 9.0, 9.0}, 1.4, Eigen::Vector3d::UnitY())};
  const CameraPose p = interpolatePose(a, b, 5.0);
  EXPECT_EQ(p.position, a.pose.position);
  EXPECT_NEAR(angleBetween(p.orientation, a.pose.orientation), 0.0, 1e-12);
}

TEST(PoseInterpolation, TrajectoryInterpolatesInsideAndHoldsOutside) {
  std::vector<TimedPose> trajectory;
  for (int q = 0; q < 5; ++q)
    trajectory.push_back(
        {1000.0 + q / 30.0, pose({0.1 * q, 0.0, 0.0}, 0.05 * q, Eigen::Vector3d::UnitY())});
  EXPECT_THROW(poseOnTrajectory({}, 1.0), InvalidArgument);
  EXPECT_NEAR(poseOnTrajectory(trajectory, 999.0).position.x(), 0.0, 1e-12);
  EXPECT_NEAR(poseOnTrajectory(trajectory, 1001.0).position.x(), 0.4, 1e-12);
  // Exactly at a sample: that sample.
  EXPECT_NEAR(poseOnTrajectory(trajectory, trajectory[2].stamp).position.x(), 0.2, 1e-12);
  const CameraPose p = poseOnTrajectory(trajectory, 1000.0 + 2.5 / 30.0);
  EXPECT_NEAR(p.position.x(), 0.25, 1e-9);
  EXPECT_NEAR(angleBetween(p.orientation,
                           Eigen::Quaterniond(Eigen::AngleAxisd(0.125, Eigen::Vector3d::UnitY()))),
              0.0, 1e-9);
}

TEST(PoseInterpolation, ComposeAndInverse) {
  const CameraPose a = pose({1.0, -2.0, 0.5}, 0.7, {1.0, 2.0, 3.0});
  const CameraPose b = pose({0.2, 0.1, -0.3}, -1.1, {0.0, 1.0, 0.2});
  const Eigen::Vector3d x(0.3, 0.4, 5.0);
  const Eigen::Vector3d direct = a.position + a.rotation() * (b.position + b.rotation() * x);
  const CameraPose ab = composePoses(a, b);
  EXPECT_NEAR((ab.position + ab.rotation() * x - direct).norm(), 0.0, 1e-12);
  const CameraPose identity = composePoses(inversePose(a), a);
  EXPECT_NEAR(identity.position.norm(), 0.0, 1e-12);
  EXPECT_NEAR(angleBetween(identity.orientation, Eigen::Quaterniond::Identity()), 0.0, 1e-12);
}

}  // namespace
}  // namespace view_selection::core
