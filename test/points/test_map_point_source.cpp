// Map point source: visibility assignment on hand-built cases, thinning, and map changes that
// update exactly the affected keyframes' rows.
#include "view_selection/core/exceptions.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/points/map_point_source.h"

#include "support/test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>
#include "support/layers.h"

namespace view_selection {
namespace {

using test::lookAt;
using test::vgaIntrinsics;

Eigen::Matrix3Xd columns(std::initializer_list<Eigen::Vector3d> list) {
  Eigen::Matrix3Xd m(3, static_cast<Eigen::Index>(list.size()));
  Eigen::Index c = 0;
  for (const auto& v : list) m.col(c++) = v;
  return m;
}

TEST(MapPointSource, VisibilityOnHandBuiltCases) {
  const PinholeIntrinsics k = vgaIntrinsics();  // f 525, 640 x 480
  const CameraPose identity;                    // at the origin, looking along +z
  MapPointSourceConfig config;
  config.max_depth = 10.0;
  const Eigen::Matrix3Xd points = columns({
      {0.0, 0.0, 2.0},    // 0: centre, visible
      {0.0, 0.0, -2.0},   // 1: behind
      {10.0, 0.0, 2.0},   // 2: projects far right of the image
      {0.0, 0.0, 20.0},   // 3: beyond max_depth
      {1.2, 0.9, 2.0},    // 4: u = 525 * 0.6 + 319.5 = 634.5, v = 475.75: inside
      {1.3, 0.0, 2.0},    // 5: u = 660.75: outside
      {0.1, 0.0, 5.0},    // 6: behind the 2 m wall of the depth image below
      {-0.1, 0.1, 2.05},  // 7: on that wall within tolerance
  });
  Eigen::Matrix3Xd v = visibleMapPoints(points, k, identity, nullptr, config);
  ASSERT_EQ(v.cols(), 4);  // 0, 4, 6, 7; not 1, 2, 3, 5
  EXPECT_EQ(v.col(0), points.col(0));
  EXPECT_EQ(v.col(1), points.col(4));
  EXPECT_EQ(v.col(2), points.col(6));
  EXPECT_EQ(v.col(3), points.col(7));

  // Without max_depth the far point is in.
  config.max_depth = 0.0;
  EXPECT_EQ(visibleMapPoints(points, k, identity, nullptr, config).cols(), 5);

  // Occlusion against a flat depth image at 2 m: the point at 5 m is hidden.
  config.max_depth = 10.0;
  DepthMap depth;
  depth.cols = 80;
  depth.rows = 60;
  depth.cell_width = depth.cell_height = 8.0;
  depth.depth.assign(80 * 60, 2.0f);
  v = visibleMapPoints(points, k, identity, &depth, config);
  ASSERT_EQ(v.cols(), 3);  // 0, 4, 7
  EXPECT_EQ(v.col(1), points.col(4));
  EXPECT_EQ(v.col(2), points.col(7));

  // A camera looking the other way sees only the point behind the first one.
  const CameraPose back = lookAt(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, -1));
  v = visibleMapPoints(points, k, back, nullptr, config);
  ASSERT_EQ(v.cols(), 1);
  EXPECT_EQ(v.col(0), points.col(1));
}

TEST(MapPointSource, ThinsEvenlyToMaxPoints) {
  Eigen::Matrix3Xd points(3, 100);
  for (int c = 0; c < 100; ++c) points.col(c) = Eigen::Vector3d(0.01 * c - 0.5, 0.0, 2.0);
  MapPointSourceConfig config;
  config.max_points = 10;
  const Eigen::Matrix3Xd v =
      visibleMapPoints(points, vgaIntrinsics(), CameraPose{}, nullptr, config);
  ASSERT_EQ(v.cols(), 10);
  for (int q = 0; q < 10; ++q) EXPECT_EQ(v.col(q), points.col(10 * q));
}

ViewSelectorConfig everyFrame() {
  ViewSelectorConfig c;
  c.keyframes.mode = KeyframeMode::kEveryFrame;
  return c;
}

Frame frameAt(double stamp, const CameraPose& pose) {
  Frame f;
  f.stamp = stamp;
  f.image_name = std::to_string(stamp) + ".png";
  f.intrinsics = vgaIntrinsics();
  f.pose = pose;
  return f;
}

/// A grid of points on the plane z = `z`, x and y in [-1, 1].
Eigen::Matrix3Xd wall(double z, int n = 21) {
  Eigen::Matrix3Xd m(3, n * n);
  for (int a = 0; a < n; ++a)
    for (int b = 0; b < n; ++b)
      m.col(a * n + b) = Eigen::Vector3d(-1.0 + 2.0 * a / (n - 1), -1.0 + 2.0 * b / (n - 1), z);
  return m;
}

TEST(MapPointSource, MapChangesUpdateOnlyAffectedRows) {
  ViewSelector selector(everyFrame(), std::make_unique<MapPointSource>());
  auto& source = dynamic_cast<MapPointSource&>(selector.pointSource());
  source.setMapPoints(wall(3.0));
  // Keyframes 0 and 1 look at the wall at z = 3, keyframe 2 the other way.
  EXPECT_EQ(selector.addFrame(frameAt(0, lookAt({0, 0, 0}, {0, 0, 3}))).points, 441u);
  EXPECT_EQ(selector.addFrame(frameAt(1, lookAt({0.3, 0, 0}, {0, 0, 3}))).points, 441u);
  EXPECT_EQ(selector.addFrame(frameAt(2, lookAt({0, 0, 0}, {0, 0, -3}))).points, 0u);
  EXPECT_TRUE(std::isfinite(selector.matrix().at(0, 1)));

  // A second wall behind the cameras: only keyframe 2 sees it.
  Eigen::Matrix3Xd both(3, 882);
  both << wall(3.0), wall(-3.0);
  source.setMapPoints(both);
  EXPECT_EQ(source.pendingUpdates(), std::vector<ViewId>{2});
  EXPECT_EQ(selector.applyPointUpdates(), std::vector<ViewId>{2});
  EXPECT_TRUE(source.pendingUpdates().empty());
  EXPECT_EQ(selector.matrix().keyframe(2).points.cols(), 441);
  EXPECT_TRUE(selector.applyPointUpdates().empty());  // nothing twice

  // Pending updates also travel with the next keyframe.
  source.setMapPoints(wall(3.0, 11));
  EXPECT_EQ(source.pendingUpdates(), (std::vector<ViewId>{0, 1, 2}));
  const FrameResult r = selector.addFrame(frameAt(3, lookAt({-0.3, 0, 0}, {0, 0, 3})));
  EXPECT_EQ(r.updated_rows, (std::vector<ViewId>{0, 1, 2}));
  EXPECT_EQ(r.points, 121u);
  EXPECT_EQ(selector.matrix().keyframe(0).points.cols(), 121);
  EXPECT_EQ(selector.matrix().keyframe(2).points.cols(), 0);
  const ErrorResistanceMatrix& m = selector.matrix();
  for (ViewId i = 0; i < 4; ++i)
    for (ViewId j = 0; j < 4; ++j)
      if (i != j) {
        EXPECT_EQ(m.at(i, j),
                  computeErrorResistance(m.keyframe(i), m.keyframe(j), selector.config().matrix));
      }
}

TEST(MapPointSource, IncrementalReassignmentEqualsAFullOne) {
  // Keyframes along a wall of map points, each looking at it; the map grows at one end, loses
  // and moves a few points there, and once comes in another order. After every map, each keyframe's assignment
  // must be what a full reassignment gives, and a map that changes only where few keyframes
  // look must project only those against it.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  MapPointSourceConfig config;
  config.max_points = 150;  // thinning on: the order of the points matters
  MapPointSource source(config);
  auto corridor = [&](double from, double to, int n) {
    Eigen::Matrix3Xd m(3, n);
    for (int c = 0; c < n; ++c)
      m.col(c) = Eigen::Vector3d(2.0, uni(rng) * 2 - 1, from + uni(rng) * (to - from));
    return m;
  };
  Eigen::Matrix3Xd map = corridor(-5.0, 25.0, 3000);
  source.setMapPoints(map);
  const int kKeyframes = 40;
  for (int i = 0; i < kKeyframes; ++i)  // 0.5 m apart, 2 m from the wall
    source.process(i, frameAt(i, lookAt({0, 0, 0.5 * i}, {2.0, 0, 0.5 * i})));
  source.takeUpdates();
  auto expectFull = [&](const std::string& where) {
    const MapPointSource::State state = source.state();
    for (const MapPointSource::View& v : state.views) {
      const Eigen::Matrix3Xd want = visibleMapPoints(map, v.intrinsics, v.pose, v.depth.get(), config);
      ASSERT_EQ(v.assigned.cols(), want.cols()) << where << ", keyframe " << v.id;
      EXPECT_TRUE(v.assigned == want) << where << ", keyframe " << v.id;
    }
  };
  for (int step = 0; step < 12; ++step) {
    const std::string where = "step " + std::to_string(step);
    if (step == 7) {
      // Another order: every keyframe is projected again.
      std::vector<Eigen::Index> order(static_cast<size_t>(map.cols()));
      std::iota(order.begin(), order.end(), 0);
      std::shuffle(order.begin(), order.end(), rng);
      Eigen::Matrix3Xd shuffled(3, map.cols());
      for (Eigen::Index c = 0; c < map.cols(); ++c) shuffled.col(c) = map.col(order[static_cast<size_t>(c)]);
      map = shuffled;
      source.setMapPoints(map);
      EXPECT_EQ(source.lastReassigned(), static_cast<size_t>(kKeyframes)) << where;
      expectFull(where);
      continue;
    }
    // New points at the far end (seen by the last keyframes only), a few moved there.
    const Eigen::Matrix3Xd added = corridor(18.5, 19.5 + 0.2 * step, 50);
    Eigen::Matrix3Xd next(3, map.cols() + added.cols());
    next << map, added;
    for (int q = 0; q < 5; ++q) {
      const Eigen::Index c = next.cols() - 1 - static_cast<Eigen::Index>(uni(rng) * 40);
      next(1, c) += 0.01;  // moved
    }
    map = next;
    source.setMapPoints(map);
    EXPECT_LT(source.lastReassigned(), static_cast<size_t>(kKeyframes))
        << where << ": keyframes that see none of the changes must keep their assignment";
    EXPECT_GT(source.lastReassigned(), 0u) << where;
    expectFull(where);
  }
  // Points gone: a map with the first 500 points dropped.
  map = Eigen::Matrix3Xd(map.rightCols(map.cols() - 500));
  source.setMapPoints(map);
  expectFull("points dropped");
}

TEST(MapPointSource, BadInputThrowsAndChangesNothing) {
  MapPointSource source;
  source.setMapPoints(wall(3.0));
  Eigen::Matrix3Xd bad = wall(3.0);
  bad(0, 5) = std::nan("");
  EXPECT_THROW(source.setMapPoints(bad), InvalidInput);
  EXPECT_EQ(source.mapPoints(), wall(3.0));
  auto badConfig = [](auto change) {
    MapPointSourceConfig c;
    change(c);
    EXPECT_THROW(MapPointSource{c}, InvalidArgument);
  };
  badConfig([](auto& c) { c.max_points = -1; });
  badConfig([](auto& c) { c.max_depth = std::nan(""); });
  badConfig([](auto& c) { c.occlusion.abs_tolerance = -0.1; });
  badConfig([](auto& c) { c.occlusion.depth_map_cell = 0; });
  source.process(0, frameAt(0, CameraPose{}));
  EXPECT_THROW(source.process(0, frameAt(1, CameraPose{})), InvalidArgument);
}

}  // namespace
}  // namespace view_selection
