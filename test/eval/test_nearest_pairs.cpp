// The "nearest" baseline: k nearest camera centres within a viewing-angle limit.
#include "support/test_support.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/eval/nearest_pairs.h"

#include <gtest/gtest.h>
#include "support/layers.h"

namespace view_selection {
namespace {

using test::lookAt;

// Cameras on a line along x at the given positions, all looking along +z (or rotated about y).
std::vector<CameraPose> lineOfCameras(const std::vector<double>& xs,
                                      const std::vector<double>& yaw_deg = {}) {
  std::vector<CameraPose> poses;
  for (size_t i = 0; i < xs.size(); ++i) {
    const double yaw = i < yaw_deg.size() ? yaw_deg[i] * M_PI / 180.0 : 0.0;
    const Eigen::Vector3d eye(xs[i], 0, 0);
    poses.push_back(lookAt(eye, eye + Eigen::Vector3d(std::sin(yaw), 0, std::cos(yaw))));
  }
  return poses;
}

TEST(NearestPairs, TakesKNearestCentresWithTiesOnLowerId) {
  // x = 0, 1, 2, 4, 7: view 1 has 0 and 2 at equal distance.
  const auto poses = lineOfCameras({0, 1, 2, 4, 7});
  NearestPairsConfig c;
  c.k = 1;
  const auto sets = nearestNeighbourSets(poses, c);
  ASSERT_EQ(sets.size(), 5u);
  EXPECT_EQ(sets[0], (std::vector<ViewId>{1}));
  EXPECT_EQ(sets[1], (std::vector<ViewId>{0}));  // tie 0 vs 2: lower id
  EXPECT_EQ(sets[2], (std::vector<ViewId>{1}));
  EXPECT_EQ(sets[3], (std::vector<ViewId>{2}));
  EXPECT_EQ(sets[4], (std::vector<ViewId>{3}));
  EXPECT_EQ(nearestPairs(poses, c),
            (std::vector<std::pair<ViewId, ViewId>>{{0, 1}, {1, 2}, {2, 3}, {3, 4}}));
  c.k = 2;
  const auto sets2 = nearestNeighbourSets(poses, c);
  EXPECT_EQ(sets2[1], (std::vector<ViewId>{0, 2}));
  EXPECT_EQ(sets2[4], (std::vector<ViewId>{3, 2}));  // nearest first
  c.k = 10;  // more than there are: everyone else, nearest first
  EXPECT_EQ(nearestNeighbourSets(poses, c)[0], (std::vector<ViewId>{1, 2, 3, 4}));
  EXPECT_EQ(nearestPairs(poses, c).size(), 10u);  // all 5*4/2 pairs
}

TEST(NearestPairs, ViewingAngleLimitExcludesNearButTurnedViews) {
  // View 1 is nearest to 0 but turned 60 degrees; with a 30-degree limit 0 pairs with 2 instead.
  const auto poses = lineOfCameras({0, 1, 3}, {0, 60, 10});
  NearestPairsConfig c;
  c.k = 1;
  c.max_view_angle_deg = 30.0;
  const auto sets = nearestNeighbourSets(poses, c);
  EXPECT_EQ(sets[0], (std::vector<ViewId>{2}));
  EXPECT_TRUE(sets[1].empty());  // nobody within 30 degrees of view 1
  EXPECT_EQ(sets[2], (std::vector<ViewId>{0}));
  EXPECT_EQ(nearestPairs(poses, c), (std::vector<std::pair<ViewId, ViewId>>{{0, 2}}));
  c.max_view_angle_deg = 60.0;  // the limit is inclusive
  EXPECT_EQ(nearestNeighbourSets(poses, c)[0], (std::vector<ViewId>{1}));
  c.max_view_angle_deg = 180.0;
  EXPECT_EQ(nearestNeighbourSets(poses, c)[1], (std::vector<ViewId>{0}));
}

TEST(NearestPairs, BadInputIsRefused) {
  const auto poses = lineOfCameras({0, 1});
  NearestPairsConfig c;
  c.k = 0;
  EXPECT_THROW(nearestPairs(poses, c), InvalidArgument);
  c.k = 2;
  c.max_view_angle_deg = 200.0;
  EXPECT_THROW(nearestPairs(poses, c), InvalidArgument);
  c.max_view_angle_deg = 30.0;
  auto bad = poses;
  bad[1].position.x() = std::nan("");
  EXPECT_THROW(nearestPairs(bad, c), InvalidArgument);
  EXPECT_TRUE(nearestPairs({}, c).empty());
  EXPECT_TRUE(nearestPairs({poses[0]}, c).empty());
}

}  // namespace
}  // namespace view_selection
