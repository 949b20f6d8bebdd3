// The package's one triangulation (refine/triangulation.h): the rules the refinement and the
// live model share.
#include "view_selection/refine/triangulation.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <vector>

namespace view_selection::refine {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// A camera at `centre` looking at the origin region along +z of the world (no rotation), with
/// a VGA pinhole; the observation of `x` shifted by `offset` pixels.
TrackObservation observe(const Eigen::Vector3d& centre, const Eigen::Vector3d& x, const Eigen::Vector2d& offset = {0, 0}) {
  TrackObservation o;
  o.R = Eigen::Matrix3d::Identity();
  o.t = -centre;
  o.k = {500.0, 500.0, 320.0, 240.0};
  const Eigen::Vector3d p = o.R * x + o.t;
  o.xy = Eigen::Vector2d(o.k[0] * p.x() / p.z() + o.k[2], o.k[1] * p.y() / p.z() + o.k[3]) + offset;
  return o;
}

std::vector<TrackObservation> row(const Eigen::Vector3d& x, int n, double spacing = 0.1) {
  std::vector<TrackObservation> track;
  for (int i = 0; i < n; ++i) track.push_back(observe({spacing * i, 0.0, 0.0}, x));
  return track;
}

TEST(Triangulation, ExactObservationsGiveThePoint) {
  const Eigen::Vector3d x(0.2, -0.1, 2.0);
  const TriangulatedPoint p = triangulateTrack(row(x, 4));
  ASSERT_TRUE(p.ok);
  EXPECT_LT((p.x - x).norm(), 1e-9);
  EXPECT_EQ((std::vector<int>{0, 1, 2, 3}), p.inliers);
  EXPECT_LT(p.mean_error, 1e-6);
}

TEST(Triangulation, AnOutlierIsDroppedAndThePointMadeFromTheRest) {
  const Eigen::Vector3d x(0.2, -0.1, 2.0);
  auto track = row(x, 5);
  track[2].xy += Eigen::Vector2d(25.0, -10.0);
  const TriangulatedPoint p = triangulateTrack(track);
  ASSERT_TRUE(p.ok);
  EXPECT_EQ((std::vector<int>{0, 1, 3, 4}), p.inliers);
  EXPECT_LT((p.x - x).norm(), 1e-9);
}

TEST(Triangulation, AnObservationBehindItsCameraIsDropped) {
  const Eigen::Vector3d x(0.0, 0.0, 2.0);
  auto track = row(x, 3);
  TrackObservation behind = observe({0.0, 0.0, 4.0}, Eigen::Vector3d(0.0, 0.0, 6.0));  // x lies behind it
  track.push_back(behind);
  const TriangulatedPoint p = triangulateTrack(track);
  ASSERT_TRUE(p.ok);
  EXPECT_EQ((std::vector<int>{0, 1, 2}), p.inliers);
}

TEST(Triangulation, TooNarrowATriangulationAngleIsNotKept) {
  const Eigen::Vector3d x(0.0, 0.0, 10.0);
  // 1 cm baseline at 10 m: 0.06 degrees, under the 1.5 degree default.
  const TriangulatedPoint p = triangulateTrack(row(x, 3, 0.005));
  EXPECT_FALSE(p.ok);
  TriangulationRule loose;
  loose.min_angle_deg = 0.01;
  EXPECT_TRUE(triangulateTrack(row(x, 3, 0.005), loose).ok);
}

TEST(Triangulation, AfterTheOneByOneRoundsEveryObservationBeyondTheLimitGoesAtOnce) {
  // Six good observations and two off by 20 px: the first point is pulled so far that good ones
  // lie beyond the limit too. Dropping the worst alone, round by round, finds the six; dropping
  // every one beyond the limit at once (no one-by-one rounds) throws good ones away with them.
  const Eigen::Vector3d x(0.1, 0.2, 3.0);
  auto track = row(x, 6, 0.15);
  track.push_back(observe({0.90, 0.0, 0.0}, x, Eigen::Vector2d(20.0, 5.0)));
  track.push_back(observe({1.05, 0.0, 0.0}, x, Eigen::Vector2d(16.0, -5.0)));
  TriangulationRule one_by_one, at_once;
  at_once.drop_one_by_one = 0;
  const auto a = triangulateTrack(track, one_by_one), b = triangulateTrack(track, at_once);
  ASSERT_TRUE(a.ok);
  EXPECT_EQ((std::vector<int>{0, 1, 2, 3, 4, 5}), a.inliers);
  EXPECT_LT((a.x - x).norm(), 1e-6);
  EXPECT_LT(b.ok ? b.inliers.size() : 0u, 6u) << "the rules did not differ on this track";
}

TEST(Triangulation, TwoObservationsThatDisagreeGiveNoPoint) {
  const Eigen::Vector3d x(0.0, 0.0, 2.0);
  auto track = row(x, 2);
  track[1].xy += Eigen::Vector2d(0.0, 30.0);  // off the epipolar line: no point fits both
  EXPECT_FALSE(triangulateTrack(track).ok);
}

}  // namespace
}  // namespace view_selection::refine
