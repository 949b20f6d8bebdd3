#include "view_selection/core/exceptions.h"
#include "view_selection/core/pose_correction.h"
#include "view_selection/core/pose_history.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

namespace view_selection::core {
namespace {

TimedPose at(double t, double x, double yaw_deg = 0.0) {
  TimedPose p;
  p.stamp = t;
  p.pose.position = Eigen::Vector3d(x, 0.0, 0.0);
  p.pose.orientation = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY());
  return p;
}

CameraPose pose(const Eigen::Vector3d& position, double angle, const Eigen::Vector3d& axis) {
  CameraPose p;
  p.position = position;
  p.orientation = Eigen::AngleAxisd(angle, axis.normalized());
  return p;
}

/// A handheld-like true path (a curve, turning) and an odometry that drifts away from it in the
/// world: 3 cm/s, 1.5 deg/s about a tilted axis.
CameraPose truth(double t) {
  return pose({0.4 * std::sin(0.8 * t), 0.1 * t, 0.3 * std::cos(0.5 * t)}, 0.4 * t + 0.2,
              {0.1, 1.0, 0.2});
}
CameraPose drift(double t) {
  return pose({0.03 * t, -0.01 * t, 0.005 * t}, 1.5 * M_PI / 180.0 * t, {0.2, 1.0, -0.1});
}
CameraPose drifted(double t) { return composePoses(drift(t), truth(t)); }

double distance(const CameraPose& a, const CameraPose& b) {
  return (a.position - b.position).norm();
}

TEST(PoseHistory, ExactInterpolatedOrNothing) {
  PoseHistory h;
  h.add(1.0, at(1.0, 0.0).pose);
  h.add(1.1, at(1.1, 1.0, 10.0).pose);
  h.add(1.05, at(1.05, 5.0).pose);  // not after the last: ignored
  h.add(1.3, at(1.3, 3.0).pose);
  EXPECT_EQ(h.size(), 3u);
  EXPECT_DOUBLE_EQ(h.at(1.1, 0.0)->position.x(), 1.0);  // exact needs no neighbours
  const auto mid = h.at(1.05, 0.06);
  ASSERT_TRUE(mid);
  EXPECT_NEAR(mid->position.x(), 0.5, 1e-12);
  EXPECT_NEAR(rotationDegrees(*mid, at(0, 0, 5.0).pose), 0.0, 1e-9);
  EXPECT_FALSE(h.at(1.05, 0.04));  // a neighbour too far
  EXPECT_FALSE(h.at(1.2, 0.05));   // 0.1 s to each side needs a gap of 0.1 ...
  EXPECT_TRUE(h.at(1.2, 0.1 + 1e-9));
  EXPECT_FALSE(h.at(0.99, 1.0));  // ... but never outside
  EXPECT_FALSE(h.at(1.31, 1.0));
  h.clear();
  EXPECT_TRUE(h.empty());
  EXPECT_FALSE(h.at(1.0, 1.0));
}

TEST(PoseCorrection, AtAPathPoseTheKeyframeTakesIt) {
  // The old behaviour, a path pose at every keyframe stamp: each takes its path pose.
  std::vector<CorrectableKeyframe> keyframes;
  std::vector<TimedPose> path;
  std::vector<std::optional<CameraPose>> sources;
  for (int i = 0; i < 5; ++i) {
    const double t = 0.5 * i;
    keyframes.push_back({t, drifted(t), drifted(t)});
    path.push_back({t, truth(t)});
    sources.push_back(drifted(t));
  }
  const auto corrections = pathCorrections(path, sources);
  ASSERT_EQ(corrections.size(), 5u);
  const auto moves = matchCorrections(keyframes, corrections, PoseCorrectionConfig{});
  ASSERT_EQ(moves.size(), 4u);  // the first had no drift yet
  for (const auto& [id, p] : moves) {
    EXPECT_LT(distance(p, truth(keyframes[id].stamp)), 1e-12);
    EXPECT_LT(rotationDegrees(p, truth(keyframes[id].stamp)), 1e-9);
  }
}

TEST(PoseCorrection, KeyframesBetweenPathPosesTakeTheInterpolatedCorrection) {
  // A VINS-like path: one pose every 7 frames (30 Hz), 7 ms off the node's frame stamps; the
  // node's keyframes every 5th frame, so almost none shares a stamp with the path.
  PoseHistory history;
  for (int f = 0; f <= 300; ++f) history.add(f / 30.0, drifted(f / 30.0));
  std::vector<TimedPose> path;
  std::vector<std::optional<CameraPose>> sources;
  for (int f = 3; f < 280; f += 7) {
    const double t = f / 30.0 + 0.007;
    path.push_back({t, truth(t)});
    sources.push_back(history.at(t, 0.1));
  }
  const auto corrections = pathCorrections(path, sources);
  EXPECT_EQ(corrections.size(), path.size());
  std::vector<CorrectableKeyframe> keyframes;
  for (int f = 0; f <= 300; f += 5)
    keyframes.push_back({f / 30.0, drifted(f / 30.0), *history.at(f / 30.0, 0.0)});
  const auto moves = matchCorrections(keyframes, corrections, PoseCorrectionConfig{});
  // All: before the first path pose the first correction holds, which moves even the keyframe at
  // t = 0 (no drift yet) by the drift of 0.1 s later, 3 mm.
  EXPECT_EQ(moves.size(), keyframes.size());
  double worst_inside = 0.0, worst_outside = 0.0, drift_max = 0.0;
  for (const auto& [id, p] : moves) {
    const double t = keyframes[id].stamp;
    const double error = distance(p, truth(t));
    drift_max = std::max(drift_max, distance(keyframes[id].pose, truth(t)));
    if (t >= path.front().stamp && t <= path.back().stamp) {
      worst_inside = std::max(worst_inside, error);
      EXPECT_LT(rotationDegrees(p, truth(t)), 0.01) << t;
    } else {
      worst_outside = std::max(worst_outside, error);
    }
  }
  // Drift of centimetres; inside the path, the interpolated correction leaves well under 1 mm
  // (the path's 0.23 s spacing, the drift rotating the correction's translation); outside it,
  // the nearest correction holds as the drift goes on (0.8 s after the last path pose: 28 mm).
  std::printf("[ measure  ] drift up to %.1f mm; after the correction %.3f mm inside the path, "
              "%.1f mm outside\n", 1e3 * drift_max, 1e3 * worst_inside, 1e3 * worst_outside);
  EXPECT_GT(drift_max, 0.2);
  EXPECT_LT(worst_inside, 5e-4);
  EXPECT_GT(worst_outside, worst_inside);
  EXPECT_LT(worst_outside, 0.04);
}

TEST(PoseCorrection, OutsideThePathTheNearestCorrectionHolds) {
  const std::vector<TimedPose> corrections{at(1.0, 0.1), at(2.0, 0.3)};
  const CameraPose source = at(0.0, 1.0).pose;
  EXPECT_DOUBLE_EQ(correctedPose(corrections, 0.5, source).position.x(), 1.1);
  EXPECT_DOUBLE_EQ(correctedPose(corrections, 1.0, source).position.x(), 1.1);
  EXPECT_NEAR(correctedPose(corrections, 1.25, source).position.x(), 1.15, 1e-12);
  EXPECT_DOUBLE_EQ(correctedPose(corrections, 2.0, source).position.x(), 1.3);
  EXPECT_DOUBLE_EQ(correctedPose(corrections, 9.0, source).position.x(), 1.3);
}

TEST(PoseCorrection, ThresholdsAndUnknownSources) {
  // Path poses whose source pose is unknown (before the session, or across a gap) give none.
  const std::vector<TimedPose> path{at(1.0, 0.001), at(2.0, 1.05), at(3.0, 2.0, 0.5)};
  const auto corrections = pathCorrections(path, {CameraPose{}, std::nullopt, at(3.0, 2.0).pose});
  ASSERT_EQ(corrections.size(), 2u);
  EXPECT_DOUBLE_EQ(corrections[0].pose.position.x(), 0.001);
  const std::vector<CorrectableKeyframe> keyframes{{1.0, {}, {}}, {3.0, at(3.0, 2.0).pose, at(3.0, 2.0).pose}};
  const auto moves = matchCorrections(keyframes, corrections, PoseCorrectionConfig{});
  ASSERT_EQ(moves.size(), 1u);  // 1 mm is below the 2 mm threshold; 0.5 degrees is not
  EXPECT_EQ(moves[0].first, 1);
  EXPECT_NEAR(rotationDegrees(moves[0].second, at(0, 0).pose), 0.5, 1e-9);
  PoseCorrectionConfig fine;
  fine.min_translation = 1e-5;
  EXPECT_EQ(matchCorrections(keyframes, corrections, fine).size(), 2u);
  EXPECT_TRUE(matchCorrections(keyframes, {}, fine).empty());
  EXPECT_THROW(pathCorrections(path, {}), InvalidArgument);
}

TEST(PoseCorrection, IndependentOfTheWorldOrigin) {
  // The same scene in a world frame moved far away and turned: the corrected poses move with it.
  const CameraPose w = pose({120.0, -45.0, 7.0}, 2.0, {1.0, 0.3, -0.4});
  std::vector<TimedPose> corrections, moved;
  for (double t : {1.0, 1.4}) {
    const TimedPose c{t, composePoses(truth(t), inversePose(drifted(t)))};
    corrections.push_back(c);
    moved.push_back({t, composePoses(composePoses(w, c.pose), inversePose(w))});
  }
  for (double t : {0.7, 1.1, 1.25, 1.39, 2.0}) {
    const CameraPose a = composePoses(w, correctedPose(corrections, t, drifted(t)));
    const CameraPose b = correctedPose(moved, t, composePoses(w, drifted(t)));
    EXPECT_LT(distance(a, b), 1e-9) << t;
    EXPECT_LT(rotationDegrees(a, b), 1e-7) << t;
  }
}

}  // namespace
}  // namespace view_selection::core
