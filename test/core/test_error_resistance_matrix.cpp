// The error-resistance matrix: incremental insertion equals a from-scratch computation in any
// insertion order, row-only recomputation, gates, occlusion, median, against a naive reference.
#include "view_selection/core/error_resistance_matrix.h"

#include "view_selection/core/camera_grid.h"

#include "view_selection/core/error_resistance.h"
#include "view_selection/core/exceptions.h"

#include "support/test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include "support/layers.h"

namespace view_selection {
namespace {

using test::lookAt;
using test::vgaIntrinsics;

/// The paper's gate (METHOD.md version 1): every visible point counts, max(10, 0.1 |X_i|).
ErrorResistanceConfig paperGate() {
  ErrorResistanceConfig config;
  config.gate = Gate::kPaper;
  return config;
}

/// METHOD.md's matchable test written out with angles, independent of the optimised form.
bool naiveMatchable(const Eigen::Vector3d& x, const Keyframe& i, const Keyframe& j,
                    const ErrorResistanceConfig& config) {
  const Eigen::Vector3d to_i = i.pose.position - x, to_j = j.pose.position - x;
  if (config.max_parallax_deg > 0.0) {
    const double angle =
        std::acos(std::clamp(to_i.dot(to_j) / (to_i.norm() * to_j.norm()), -1.0, 1.0));
    if (angle * 180.0 / M_PI > config.max_parallax_deg) return false;
  }
  if (config.max_scale_ratio > 0.0) {
    const double f_i = std::sqrt(i.intrinsics.fx * i.intrinsics.fy);
    const double f_j = std::sqrt(j.intrinsics.fx * j.intrinsics.fy);
    const double s = (to_j.norm() / f_j) / (to_i.norm() / f_i);
    if (std::max(s, 1.0 / s) > config.max_scale_ratio) return false;
  }
  return true;
}

/// The definition of METHOD.md written out plainly, independent of the optimised code path.
double naiveEntry(const Keyframe& i, const Keyframe& j, const ErrorResistanceConfig& requested) {
  const ErrorResistanceConfig config = requested.inForce();
  const double needed =
      std::max<double>(config.min_covisible_points, config.min_covisible_ratio * i.points.cols());
  if (config.max_view_angle_deg > 0.0) {
    const double angle =
        std::acos(std::clamp(i.pose.opticalAxis().dot(j.pose.opticalAxis()), -1.0, 1.0));
    if (angle * 180.0 / M_PI > config.max_view_angle_deg) return kInfinity;
  }
  std::vector<double> values;
  for (Eigen::Index c = 0; c < i.points.cols(); ++c) {
    const Eigen::Vector3d p = i.points.col(c);
    const Eigen::Vector3d pc = j.pose.worldToCamera(p);
    if (pc.z() <= 0.0) continue;
    const Eigen::Vector2d px = j.intrinsics.project(pc);
    if (!j.intrinsics.inImage(px)) continue;
    if (j.depth) {
      const double d = j.depth->at(px.x(), px.y());
      if (d > 0.0 && std::abs(pc.z() - d) > std::max(config.occlusion.abs_tolerance,
                                                     config.occlusion.rel_tolerance * pc.z()))
        continue;
    }
    if (!naiveMatchable(p, i, j, config)) continue;
    values.push_back(pointErrorResistance(p, i.pose.position, j.intrinsics, j.pose));
  }
  if (values.size() < needed) return kInfinity;
  std::sort(values.begin(), values.end());
  const size_t m = values.size() / 2;
  return values.size() % 2 ? values[m] : 0.5 * (values[m - 1] + values[m]);
}

/// A room of points on its walls with cameras inside looking at random walls; each keyframe
/// keeps the points it sees (z-buffered) and, for some, a coarse depth map.
struct Scene {
  std::vector<Keyframe> keyframes;
};

Scene makeScene(unsigned seed, int views, bool with_depth) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  // Walls of a 6 x 3 x 5 box plus a free-standing panel that occludes part of the room.
  std::vector<Eigen::Vector3d> world;
  for (int q = 0; q < 4000; ++q) {
    const int wall = static_cast<int>(uni(rng) * 5);
    const double a = uni(rng), b = uni(rng);
    switch (wall) {
      case 0:
        world.emplace_back(-3.0, 3.0 * a - 1.5, 5.0 * b - 2.5);
        break;
      case 1:
        world.emplace_back(3.0, 3.0 * a - 1.5, 5.0 * b - 2.5);
        break;
      case 2:
        world.emplace_back(6.0 * a - 3.0, 3.0 * b - 1.5, -2.5);
        break;
      case 3:
        world.emplace_back(6.0 * a - 3.0, 3.0 * b - 1.5, 2.5);
        break;
      default:
        world.emplace_back(1.5 * a - 0.75, 1.5 * b - 0.75, 0.0);
        break;  // panel
    }
  }
  Scene scene;
  for (int v = 0; v < views; ++v) {
    // Drawn one by one, z first: as function arguments (unspecified order) gcc drew them last
    // first and clang first first, which made the scene, and this test, compiler-dependent.
    const double ez = uni(rng), ey = uni(rng), ex = uni(rng);
    const Eigen::Vector3d eye(4.0 * ex - 2.0, 0.6 * ey - 0.3, 3.0 * ez - 1.5);
    const double tz = uni(rng), ty = uni(rng), tx = uni(rng);
    const Eigen::Vector3d target(6.0 * tx - 3.0, 0.5 * ty - 0.25, 5.0 * tz - 2.5);
    if ((target - eye).norm() < 0.5) {
      --v;
      continue;
    }
    Keyframe kf;
    kf.stamp = v;
    kf.image_name = std::to_string(v) + ".png";
    kf.intrinsics = vgaIntrinsics(400.0 + 200.0 * uni(rng));
    kf.pose = lookAt(eye, target, 0.2 * uni(rng) - 0.1);
    // z-buffer on 8 x 8 cells: the nearest point per cell is what this camera sees there.
    auto map = std::make_shared<DepthMap>();
    map->cols = 80;
    map->rows = 60;
    map->cell_width = map->cell_height = 8.0;
    map->depth.assign(80 * 60, 0.0f);
    std::vector<std::pair<int, Eigen::Vector3d>> seen;
    for (const auto& p : world) {
      const Eigen::Vector3d pc = kf.pose.worldToCamera(p);
      if (pc.z() <= 0.1) continue;
      const Eigen::Vector2d px = kf.intrinsics.project(pc);
      if (!kf.intrinsics.inImage(px)) continue;
      const int cell = static_cast<int>(px.y() / 8) * 80 + static_cast<int>(px.x() / 8);
      float& d = map->depth[static_cast<size_t>(cell)];
      if (d == 0.0f || pc.z() < d) d = static_cast<float>(pc.z());
      seen.emplace_back(cell, p);
    }
    std::vector<Eigen::Vector3d> kept;
    for (const auto& [cell, p] : seen)
      if (std::abs(kf.pose.worldToCamera(p).z() - map->depth[static_cast<size_t>(cell)]) < 0.05 &&
          kept.size() < 120)
        kept.push_back(p);
    kf.points.resize(3, static_cast<Eigen::Index>(kept.size()));
    for (size_t q = 0; q < kept.size(); ++q) kf.points.col(static_cast<Eigen::Index>(q)) = kept[q];
    if (with_depth && v % 3 != 2) kf.depth = map;  // some views without depth maps
    scene.keyframes.push_back(std::move(kf));
  }
  return scene;
}

TEST(ErrorResistanceMatrix, OptimisedEntryMatchesNaiveDefinition) {
  const Scene scene = makeScene(11, 24, true);
  ErrorResistanceConfig config;
  int finite = 0, infinite = 0;
  for (const auto& a : scene.keyframes) {
    for (const auto& b : scene.keyframes) {
      if (&a == &b) continue;
      const double fast = computeErrorResistance(a, b, config);
      const double slow = naiveEntry(a, b, config);
      if (std::isfinite(slow)) {
        ++finite;
        ASSERT_NEAR(fast, slow, 1e-12 * slow);
      } else {
        ++infinite;
        ASSERT_EQ(fast, kInfinity);
      }
    }
  }
  // The scene must exercise both outcomes, or this test would prove little.
  EXPECT_GT(finite, 40);
  EXPECT_GT(infinite, 40);
}

TEST(ErrorResistanceMatrix, CullsAreConservativeUnderEveryGate) {
  // The pair- and group-level bounds on parallax and footprint ratio may only skip points that
  // the per-point test would reject: every entry equals the naive one, for tight and loose gates.
  const Scene scene = makeScene(17, 18, true);
  std::vector<ErrorResistanceConfig> configs(8);
  for (auto& c : configs) c.min_covisible_ratio = 0.1;  // enough finite entries to compare
  configs[0].gate = Gate::kPaper;
  configs[1].max_parallax_deg = 10.0;
  configs[2].max_parallax_deg = 20.0;
  configs[3].max_parallax_deg = 60.0;
  configs[4].max_scale_ratio = 1.2;
  configs[5].max_scale_ratio = 0.0;
  configs[6].max_parallax_deg = 0.0;
  configs[7].max_parallax_deg = 0.0;
  configs[7].max_scale_ratio = 0.0;
  for (size_t c = 0; c < configs.size(); ++c) {
    int finite = 0, infinite = 0;
    for (const auto& a : scene.keyframes) {
      for (const auto& b : scene.keyframes) {
        if (&a == &b) continue;
        const double fast = computeErrorResistance(a, b, configs[c]);
        const double slow = naiveEntry(a, b, configs[c]);
        if (std::isfinite(slow)) {
          ++finite;
          ASSERT_NEAR(fast, slow, 1e-12 * slow) << "config " << c;
        } else {
          ++infinite;
          ASSERT_EQ(fast, kInfinity) << "config " << c;
        }
      }
    }
    EXPECT_GT(finite, 10) << "config " << c;
    EXPECT_GT(infinite, 10) << "config " << c;
  }
}

TEST(ErrorResistanceMatrix, IncrementalEqualsFromScratchInAnyInsertionOrder) {
  const Scene scene = makeScene(5, 20, true);
  const size_t n = scene.keyframes.size();
  ErrorResistanceConfig config;
  config.max_view_angle_deg = 100.0;  // exercise the optional gate too
  config.min_covisible_ratio = 0.2;   // enough finite entries in this small room to compare
  std::mt19937 rng(99);
  for (int trial = 0; trial < 4; ++trial) {
    std::vector<size_t> perm(n);
    std::iota(perm.begin(), perm.end(), 0);
    if (trial > 0) std::shuffle(perm.begin(), perm.end(), rng);
    ErrorResistanceMatrix matrix(config);
    for (size_t q = 0; q < n; ++q) {
      EXPECT_EQ(matrix.addKeyframe(scene.keyframes[perm[q]]), static_cast<ViewId>(q));
      // After every insertion the matrix so far equals the from-scratch values.
      for (size_t a = 0; a <= q; ++a)
        for (size_t b = 0; b <= q; ++b) {
          const double expected = a == b ? kInfinity
                                         : computeErrorResistance(scene.keyframes[perm[a]],
                                                                  scene.keyframes[perm[b]], config);
          ASSERT_EQ(matrix.at(static_cast<ViewId>(a), static_cast<ViewId>(b)), expected)
              << "trial " << trial << " after " << q << " at " << a << "," << b;
        }
    }
    EXPECT_GT(matrix.table().finiteCount(), n);
  }
}

/// A rigid nudge: up to `metres` of translation and `degrees` of rotation about a random axis.
CameraPose nudged(const CameraPose& pose, std::mt19937& rng, double metres, double degrees) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  CameraPose out = pose;
  out.position += metres * Eigen::Vector3d(u(rng), u(rng), u(rng));
  const Eigen::Vector3d axis = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
  out.orientation =
      (Eigen::AngleAxisd(degrees * M_PI / 180.0 * u(rng), axis) * pose.orientation).normalized();
  return out;
}

// The property of loop-closure corrections: after any sequence of insertions and corrections,
// the matrix equals one computed from scratch on the corrected keyframes, whose points kept
// their camera-frame coordinates.
TEST(ErrorResistanceMatrix, AfterInsertionsAndCorrectionsEqualsFromScratchOnCorrectedPoses) {
  for (const bool paper : {false, true}) {
    const Scene scene = makeScene(paper ? 21 : 17, 22, true);
    ErrorResistanceConfig config = paper ? paperGate() : ErrorResistanceConfig{};
    if (!paper) {  // wide random baselines: a looser matchable gate, so that entries exist
      config.max_parallax_deg = 40.0;
      config.min_covisible_ratio = 0.1;
    }
    std::mt19937 rng(paper ? 5 : 3);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    ErrorResistanceMatrix matrix(config);
    std::vector<Eigen::Matrix3Xd> in_camera;  // X_i in camera i's frame, at insertion
    std::vector<CameraPose> poses;            // the poses of record
    size_t next = 0, corrections = 0;
    for (int step = 0; step < 40; ++step) {
      if (next < scene.keyframes.size() && (matrix.size() < 3 || uni(rng) < 0.5)) {
        const Keyframe& k = scene.keyframes[next++];
        Eigen::Matrix3Xd c(3, k.points.cols());
        for (Eigen::Index q = 0; q < k.points.cols(); ++q)
          c.col(q) = k.pose.worldToCamera(k.points.col(q));
        in_camera.push_back(c);
        poses.push_back(k.pose);
        matrix.addKeyframe(k);
      } else {
        // Some keyframes, a contiguous run or scattered, moved by small corrections.
        std::vector<std::pair<ViewId, CameraPose>> moves;
        const size_t n = matrix.size();
        const size_t first = static_cast<size_t>(uni(rng) * n);
        for (size_t i = 0; i < n; ++i) {
          const bool run = i >= first && i < first + 1 + n / 4;
          if (run || uni(rng) < 0.1) {
            moves.emplace_back(static_cast<ViewId>(i), nudged(poses[i], rng, 0.1, 3.0));
            poses[i] = moves.back().second;
          }
        }
        matrix.setPoses(moves);
        ++corrections;
      }
      // From scratch on the keyframes as corrected: the same matrix (the same finite entries,
      // values to rounding: adding a stored keyframe again normalises its unit quaternion again).
      ErrorResistanceMatrix fresh(config);
      for (size_t i = 0; i < matrix.size(); ++i)
        fresh.addKeyframe(matrix.keyframe(static_cast<ViewId>(i)));
      ASSERT_EQ(fresh.table().finiteCount(), matrix.table().finiteCount()) << "step " << step;
      for (size_t a = 0; a < matrix.size(); ++a)
        for (const TableEntry& e : matrix.table().row(static_cast<ViewId>(a)))
          ASSERT_NEAR(fresh.at(static_cast<ViewId>(a), e.view), e.value, 1e-12 * e.value)
              << "step " << step << " E[" << a << "][" << e.view << "]";
      // And the corrected keyframes are what the corrections say: poses of record, points
      // that kept their camera-frame coordinates; E against keyframes rebuilt independently.
      std::vector<Keyframe> rebuilt;
      for (size_t i = 0; i < matrix.size(); ++i) {
        const Keyframe& k = matrix.keyframe(static_cast<ViewId>(i));
        EXPECT_LT((k.pose.position - poses[i].position).norm(), 1e-12);
        EXPECT_LT(k.pose.orientation.angularDistance(poses[i].orientation), 1e-9);
        Keyframe r = k;
        for (Eigen::Index q = 0; q < k.points.cols(); ++q) {
          ASSERT_LT((k.pose.worldToCamera(k.points.col(q)) - in_camera[i].col(q)).norm(), 1e-9);
          r.points.col(q) = poses[i].position + poses[i].rotation() * in_camera[i].col(q);
        }
        rebuilt.push_back(std::move(r));
      }
      for (size_t a = 0; a < rebuilt.size(); ++a)
        for (size_t b = 0; b < rebuilt.size(); ++b) {
          if (a == b) continue;
          const double want = computeErrorResistance(rebuilt[a], rebuilt[b], config);
          const double got = matrix.at(static_cast<ViewId>(a), static_cast<ViewId>(b));
          ASSERT_EQ(std::isfinite(got), std::isfinite(want))
              << "step " << step << " " << a << "," << b;
          if (std::isfinite(want)) {
            ASSERT_NEAR(got, want, 1e-9 * want);
          }
        }
    }
    EXPECT_GE(corrections, 8u);
    EXPECT_GT(matrix.table().finiteCount(), matrix.size());
  }
}

TEST(ErrorResistanceMatrix, SetPosesRejectsBadInputAndKeepsState) {
  const Scene scene = makeScene(5, 4, true);
  ErrorResistanceMatrix matrix;
  for (const auto& k : scene.keyframes) matrix.addKeyframe(k);
  const ErrorResistanceTable before = matrix.table();
  CameraPose bad;
  bad.position.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(matrix.setPoses({{9, CameraPose{}}}), InvalidArgument);
  EXPECT_THROW(matrix.setPoses({{1, CameraPose{}}, {1, CameraPose{}}}), InvalidArgument);
  EXPECT_THROW(matrix.setPoses({{0, matrix.keyframe(0).pose}, {1, bad}}), InvalidInput);
  EXPECT_TRUE(matrix.table() == before);
  EXPECT_EQ(matrix.keyframe(1).pose.position, scene.keyframes[1].pose.position);
}

TEST(ErrorResistanceMatrix, SpatialIndexSkipsOnlyPairsTheFootprintGateRejects) {
  // Rooms side by side at growing distances, cameras of different focal lengths: with the
  // footprint-ratio gate on, insertion looks only at the keyframes the camera grid returns.
  // Every entry must still equal the naive definition, including pairs across rooms that are
  // just within the reach bound, under tight and loose ratios.
  std::vector<Keyframe> keyframes;
  const double offsets[] = {0.0, 7.0, 15.0, 40.0, 41.5, 200.0};
  unsigned seed = 31;
  for (const double dx : offsets) {
    Scene room = makeScene(seed++, 6, true);
    for (auto& kf : room.keyframes) {
      kf.pose.position.x() += dx;
      kf.points.row(0).array() += dx;
      keyframes.push_back(std::move(kf));
    }
  }
  const size_t n = keyframes.size();
  for (const double ratio : {1.2, 1.6, 3.0, 20.0}) {
    ErrorResistanceConfig config;
    config.max_scale_ratio = ratio;
    config.max_parallax_deg = 0.0;  // the footprint gate alone bounds the distance
    config.min_covisible_ratio = 0.05;
    ErrorResistanceMatrix matrix(config);
    for (const auto& kf : keyframes) matrix.addKeyframe(kf);
    int finite = 0;
    for (size_t a = 0; a < n; ++a)
      for (size_t b = 0; b < n; ++b) {
        if (a == b) continue;
        const double expected = naiveEntry(keyframes[a], keyframes[b], config);
        const double got = matrix.at(static_cast<ViewId>(a), static_cast<ViewId>(b));
        if (std::isfinite(expected)) {
          ++finite;
          ASSERT_NEAR(got, expected, 1e-12 * expected) << "ratio " << ratio << " at " << a << "," << b;
        } else {
          ASSERT_EQ(got, kInfinity) << "ratio " << ratio << " at " << a << "," << b;
        }
      }
    EXPECT_GT(finite, static_cast<int>(n) / 2) << "ratio " << ratio;
    // The far room (200 m away) is never evaluated against the others under a tight ratio.
    if (ratio <= 1.6) {
      EXPECT_LT(matrix.pairsEvaluated(), n * (n - 1) - 2 * 6 * (n - 6));
    }
  }
}

/// Keyframe q of a corridor walk along +z (1 m apart, walls at x = +-2, y = +-1.5), 64 points
/// on the walls 4-10 m ahead; `far` of them (in place of near ones) `far_at` metres ahead.
Keyframe corridorKeyframe(int q, std::mt19937& rng, int far = 0, double far_at = 0.0) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  Keyframe kf;
  kf.stamp = q;
  kf.intrinsics = vgaIntrinsics();
  const Eigen::Vector3d eye(0.0, 0.0, 1.0 * q);
  kf.pose = lookAt(eye, eye + Eigen::Vector3d(0.0, 0.0, 1.0));
  kf.points.resize(3, 64);
  for (int c = 0; c < 64; ++c) {
    const double dz = c < far ? far_at : 4.0 + 6.0 * uni(rng);
    const bool side = uni(rng) < 0.5;
    const double s = uni(rng) < 0.5 ? -1.0 : 1.0;
    kf.points.col(c) = side ? Eigen::Vector3d(2.0 * s, -1.5 + 3.0 * uni(rng), eye.z() + dz)
                            : Eigen::Vector3d(-2.0 + 4.0 * uni(rng), 1.5 * s, eye.z() + dz);
  }
  return kf;
}

TEST(ErrorResistanceMatrix, AFarReachingKeyframeDoesNotWidenLaterSearches) {
  // Keyframe 20 sees a few points (fewer than the co-visibility gate needs) 10 km away, keyframe
  // 40 sees every point 10 km away (a real far reach). Later insertions still look at a bounded
  // number of keyframes, and every entry equals the naive definition.
  ErrorResistanceConfig config;  // matchable: footprint ratio 1.6, co-visibility 10 / 0.5
  config.min_covisible_ratio = 0.2;
  for (const bool reset_far : {false, true}) {
    std::mt19937 rng(5);
    ErrorResistanceMatrix matrix(config);
    std::vector<Keyframe> keyframes;
    std::vector<size_t> examined;
    for (int q = 0; q < 400; ++q) {
      const Keyframe kf = q == 20   ? corridorKeyframe(q, rng, 5, 1e4)
                          : q == 40 ? corridorKeyframe(q, rng, 64, 1e4)
                                    : corridorKeyframe(q, rng);
      const size_t before = matrix.candidatesExamined();
      matrix.addKeyframe(kf);
      examined.push_back(matrix.candidatesExamined() - before);
      keyframes.push_back(kf);
      if (reset_far && q == 200) {
        // The far points replaced by near ones: the large reach is gone.
        Keyframe near = corridorKeyframe(40, rng);
        matrix.setPoints(40, near.points);
        keyframes[40].points = near.points;
      }
    }
    // Bounded by the largest reach, an insertion would look at every keyframe twice (row and
    // column: 2 q); here at the ones within a few reaches, whatever n is.
    // (Below ~220 keyframes the grid compares every centre: fewer than the cells a query spans.)
    for (int q = 300; q < 400; ++q)
      ASSERT_LT(examined[static_cast<size_t>(q)], 250u) << "insertion " << q;
    size_t late = 0;
    for (int q = 380; q < 400; ++q) late += examined[static_cast<size_t>(q)];
    EXPECT_LT(late / 20, 250u);
    const size_t n = keyframes.size();
    int finite = 0;
    for (size_t a = 0; a < n; ++a)
      for (size_t b = 0; b < n; ++b) {
        if (a == b) continue;
        const double expected = naiveEntry(keyframes[a], keyframes[b], config);
        const double got = matrix.at(static_cast<ViewId>(a), static_cast<ViewId>(b));
        if (std::isfinite(expected)) {
          ++finite;
          ASSERT_NEAR(got, expected, 1e-12 * expected) << a << "," << b;
        } else {
          ASSERT_EQ(got, kInfinity) << a << "," << b;
        }
      }
    EXPECT_GT(finite, static_cast<int>(n));
  }
}

TEST(CameraGrid, GrowsCoarserForARunOfLargeQueriesAndFinerAgainAfter) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uni(-100.0, 100.0);
  std::vector<Eigen::Vector3d> centres;
  CameraGrid grid;
  for (int q = 0; q < 2000; ++q) {
    centres.emplace_back(uni(rng), uni(rng), 0.01 * uni(rng));
    grid.insert(static_cast<ViewId>(q), centres.back());
  }
  std::vector<ViewId> got;
  const auto check = [&](const Eigen::Vector3d& at, double radius) {
    grid.query(at, radius, got);
    std::vector<ViewId> expected;
    for (size_t q = 0; q < centres.size(); ++q)
      if ((centres[q] - at).norm() <= radius) expected.push_back(static_cast<ViewId>(q));
    ASSERT_EQ(got, expected) << "radius " << radius;
  };
  check(Eigen::Vector3d::Zero(), 2.0);
  const double fine = grid.cellSize();
  // One outlier's large query: answered, no regrid; it looks at no more than every centre.
  check(Eigen::Vector3d::Zero(), 500.0);
  EXPECT_EQ(grid.cellSize(), fine);
  EXPECT_LE(grid.lastExamined(), centres.size());
  check(Eigen::Vector3d(1.0, 1.0, 0.0), 2.0);
  EXPECT_LT(grid.lastExamined(), 40u);
  // A run of large queries: coarser.
  for (int q = 0; q < 4; ++q) check(Eigen::Vector3d(uni(rng), uni(rng), 0.0), 300.0);
  EXPECT_GT(grid.cellSize(), 10.0 * fine);
  // Then small ones again: after a run of them, as fine as before, and small queries look at
  // a few centres, not at every one.
  for (int q = 0; q < 40; ++q) check(Eigen::Vector3d(uni(rng), uni(rng), 0.0), 2.0);
  EXPECT_EQ(grid.cellSize(), fine);
  size_t most = 0;
  for (int q = 0; q < 20; ++q) {
    check(Eigen::Vector3d(uni(rng), uni(rng), 0.0), 2.0);
    most = std::max(most, grid.lastExamined());
  }
  EXPECT_LT(most, 40u);
}

TEST(CameraGrid, QueryEqualsBruteForceAtEveryRadius) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-50.0, 50.0);
  std::vector<Eigen::Vector3d> centres;
  CameraGrid grid;
  for (int q = 0; q < 600; ++q) {
    // Clusters and a spread, so some cells hold many centres and some none.
    const Eigen::Vector3d c = q % 3 ? Eigen::Vector3d(uni(rng), uni(rng), 0.01 * uni(rng))
                                    : Eigen::Vector3d(0.02 * uni(rng), 0.02 * uni(rng), 0.0);
    grid.insert(static_cast<ViewId>(q), c);
    centres.push_back(c);
  }
  std::vector<ViewId> got;
  // Radii that start small (fine cells) then grow past the regrid limit, and shrink again.
  for (const double radius : {0.5, 2.0, 0.1, 10.0, 40.0, 1.0, 120.0, 0.01}) {
    for (int trial = 0; trial < 20; ++trial) {
      const Eigen::Vector3d at(uni(rng), uni(rng), uni(rng) * 0.01);
      grid.query(at, radius, got);
      std::vector<ViewId> expected;
      for (size_t q = 0; q < centres.size(); ++q)
        if ((centres[q] - at).norm() <= radius) expected.push_back(static_cast<ViewId>(q));
      ASSERT_EQ(got, expected) << "radius " << radius << " trial " << trial;
    }
  }
  EXPECT_EQ(grid.size(), centres.size());
}

TEST(CameraGrid, MovedCentresAreFoundWhereTheyAreNow) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uni(-30.0, 30.0);
  std::vector<Eigen::Vector3d> centres;
  CameraGrid grid;
  std::vector<ViewId> got;
  for (int q = 0; q < 300; ++q) {
    centres.emplace_back(uni(rng), uni(rng), 0.1 * uni(rng));
    grid.insert(static_cast<ViewId>(q), centres.back());
  }
  grid.query(Eigen::Vector3d::Zero(), 2.0, got);  // fixes the cell size
  for (int round = 0; round < 5; ++round) {
    for (int m = 0; m < 60; ++m) {  // far moves (other cells) and small ones (the same cell)
      const size_t id = static_cast<size_t>(rng() % centres.size());
      const Eigen::Vector3d to = m % 2 ? Eigen::Vector3d(uni(rng), uni(rng), 0.1 * uni(rng))
                                       : Eigen::Vector3d(centres[id] + 0.01 * Eigen::Vector3d::Ones());
      grid.move(static_cast<ViewId>(id), to);
      centres[id] = to;
    }
    for (const double radius : {1.0, 3.0, 12.0}) {
      for (int trial = 0; trial < 20; ++trial) {
        const Eigen::Vector3d at(uni(rng), uni(rng), 0.0);
        grid.query(at, radius, got);
        std::vector<ViewId> expected;
        for (size_t q = 0; q < centres.size(); ++q)
          if ((centres[q] - at).norm() <= radius) expected.push_back(static_cast<ViewId>(q));
        ASSERT_EQ(got, expected) << "round " << round << " radius " << radius;
      }
    }
  }
}

TEST(ErrorResistanceMatrix, CorrectionsThatMoveKeyframesFarKeepTheSpatialIndexExact) {
  // Keyframes of one room moved (a loop closure) into a room 40 m away, then more keyframes of
  // that room inserted: with the footprint-ratio gate's spatial index, every entry must equal
  // the naive definition on the keyframes as they are now, so the index must follow the moves.
  // One room's keyframes: the first 8 stay, the other 12 are of the same room 40 m along x.
  const Scene room = makeScene(41, 20, true);
  Scene near, far;
  near.keyframes.assign(room.keyframes.begin(), room.keyframes.begin() + 8);
  far.keyframes.assign(room.keyframes.begin() + 8, room.keyframes.end());
  const double dx = 40.0;
  for (auto& kf : far.keyframes) {
    kf.pose.position.x() += dx;
    kf.points.row(0).array() += dx;
  }
  ErrorResistanceConfig config;
  config.max_parallax_deg = 0.0;
  config.min_covisible_ratio = 0.05;
  ErrorResistanceMatrix matrix(config);
  for (const auto& kf : near.keyframes) matrix.addKeyframe(kf);
  for (int q = 0; q < 6; ++q) matrix.addKeyframe(far.keyframes[static_cast<size_t>(q)]);
  // The first four keyframes of the near room were really in the far room: shifted by dx.
  std::vector<std::pair<ViewId, CameraPose>> moves;
  for (ViewId id = 0; id < 4; ++id) {
    CameraPose p = matrix.keyframe(id).pose;
    p.position.x() += dx;
    moves.emplace_back(id, p);
  }
  matrix.setPoses(moves);
  for (size_t q = 6; q < far.keyframes.size(); ++q) matrix.addKeyframe(far.keyframes[q]);
  const size_t n = matrix.size();
  int finite_across = 0;
  for (size_t a = 0; a < n; ++a)
    for (size_t b = 0; b < n; ++b) {
      if (a == b) continue;
      const double expected =
          naiveEntry(matrix.keyframe(static_cast<ViewId>(a)), matrix.keyframe(static_cast<ViewId>(b)), config);
      const double got = matrix.at(static_cast<ViewId>(a), static_cast<ViewId>(b));
      if (std::isfinite(expected)) {
        ASSERT_NEAR(got, expected, 1e-9 * expected) << a << "," << b;
        // A moved keyframe and one inserted after the move: found only through the moved centre.
        if ((a < 4 && b >= near.keyframes.size() + 6) || (b < 4 && a >= near.keyframes.size() + 6))
          ++finite_across;
      } else {
        ASSERT_EQ(got, kInfinity) << a << "," << b;
      }
    }
  EXPECT_GT(finite_across, 0) << "the test needs pairs between moved and later keyframes";
}

TEST(ErrorResistanceMatrix, ChangingPointsRecomputesOnlyThatRow) {
  Scene scene = makeScene(3, 16, true);
  const size_t n = scene.keyframes.size();
  ErrorResistanceMatrix matrix;
  for (const auto& kf : scene.keyframes) matrix.addKeyframe(kf);
  const auto before = matrix.table().dense();
  const size_t evaluated_before = matrix.pairsEvaluated();

  // Give view 4 the points of view 5 plus its own: its row changes, nothing else may.
  const ViewId changed = 4;
  Eigen::Matrix3Xd merged(3, scene.keyframes[4].points.cols() + scene.keyframes[5].points.cols());
  merged << scene.keyframes[4].points, scene.keyframes[5].points;
  matrix.setPoints(changed, merged);
  EXPECT_LE(matrix.pairsEvaluated() - evaluated_before, n - 1);  // one row at most

  scene.keyframes[4].points = merged;
  const auto after = matrix.table().dense();
  bool row_changed = false;
  for (size_t a = 0; a < n; ++a)
    for (size_t b = 0; b < n; ++b) {
      const double expected =
          a == b ? kInfinity : computeErrorResistance(scene.keyframes[a], scene.keyframes[b], {});
      ASSERT_EQ(after[a][b], expected);
      if (static_cast<ViewId>(a) != changed) {
        ASSERT_EQ(after[a][b], before[a][b]);
      }
      row_changed |= after[a][b] != before[a][b];
    }
  EXPECT_TRUE(row_changed);
  EXPECT_THROW(matrix.setPoints(static_cast<ViewId>(n), merged), InvalidArgument);
}

/// Two cameras 1 m apart looking at a grid of `count` points 3 m ahead.
std::pair<Keyframe, Keyframe> twoViews(int count) {
  Keyframe a, b;
  a.intrinsics = b.intrinsics = vgaIntrinsics();
  a.pose = lookAt({0, 0, 0}, {0.5, 0, 3});
  b.pose = lookAt({1, 0, 0}, {0.5, 0, 3});
  a.points.resize(3, count);
  for (int q = 0; q < count; ++q)
    a.points.col(q) = Eigen::Vector3d(0.5 + 0.05 * (q % 10), 0.05 * (q / 10), 3.0);
  return {a, b};
}

TEST(ErrorResistanceMatrix, MatchableGateCountsOnlyMatchablePoints) {
  auto [a, b] = twoViews(30);  // 1 m baseline at 3 m: about 19 degrees of parallax
  ErrorResistanceConfig config;
  config.max_scale_ratio = 0.0;
  config.max_parallax_deg = 25.0;
  EXPECT_TRUE(std::isfinite(computeErrorResistance(a, b, config)));
  config.max_parallax_deg = 15.0;
  EXPECT_EQ(computeErrorResistance(a, b, config), kInfinity);
  // gate paper ignores the limits: the paper's visible points count.
  config.gate = Gate::kPaper;
  ErrorResistanceConfig version1;  // every visible point counts
  version1.max_parallax_deg = 0.0;
  version1.max_scale_ratio = 0.0;
  EXPECT_TRUE(std::isfinite(computeErrorResistance(a, b, config)));
  EXPECT_EQ(computeErrorResistance(a, b, config), computeErrorResistance(a, b, version1));
  // Footprint ratio: b twice as far from the points as a (3 m vs 6 m, same focal length).
  Keyframe far = b;
  far.pose = lookAt({0.5, 0, -3.0}, {0.5, 0, 3});
  ErrorResistanceConfig scale;
  scale.max_parallax_deg = 0.0;
  scale.max_scale_ratio = 2.2;
  EXPECT_TRUE(std::isfinite(computeErrorResistance(a, far, scale)));
  scale.max_scale_ratio = 1.8;
  EXPECT_EQ(computeErrorResistance(a, far, scale), kInfinity);
  // The same ratio with b's focal length doubled is a footprint ratio of 1: it counts.
  far.intrinsics.fx *= 2.0;
  far.intrinsics.fy *= 2.0;
  EXPECT_TRUE(std::isfinite(computeErrorResistance(a, far, scale)));
  // Limits out of range are refused.
  ErrorResistanceConfig bad;
  bad.max_scale_ratio = 0.5;
  EXPECT_THROW(bad.validate(), InvalidArgument);
  bad.max_scale_ratio = 0.0;
  bad.max_parallax_deg = 200.0;
  EXPECT_THROW(bad.validate(), InvalidArgument);
}

TEST(ErrorResistanceMatrix, CovisibilityGate) {
  const ErrorResistanceConfig config = paperGate();  // max(10, 0.1 |X_i|)
  {
    auto [a, b] = twoViews(10);
    EXPECT_TRUE(std::isfinite(computeErrorResistance(a, b, config)));
    auto [c, d] = twoViews(9);
    EXPECT_EQ(computeErrorResistance(c, d, config), kInfinity);
  }
  {
    // 200 points of which 20 visible passes (0.1 * 200 = 20); 19 visible does not.
    auto [a, b] = twoViews(20);
    Eigen::Matrix3Xd points(3, 200);
    points.leftCols(20) = a.points;
    for (int q = 20; q < 200; ++q) points.col(q) = Eigen::Vector3d(0.5, 0.0, -3.0);  // behind b
    a.points = points;
    EXPECT_TRUE(std::isfinite(computeErrorResistance(a, b, config)));
    a.points.col(0) = Eigen::Vector3d(0.5, 0.0, -3.0);
    EXPECT_EQ(computeErrorResistance(a, b, config), kInfinity);
  }
}

TEST(ErrorResistanceMatrix, OcclusionAgainstTheOtherViewsDepthMap) {
  auto [a, b] = twoViews(30);
  auto wall = std::make_shared<DepthMap>();
  wall->cols = 80;
  wall->rows = 60;
  wall->cell_width = wall->cell_height = 8.0;
  wall->depth.assign(80 * 60, 1.0f);  // b sees a surface 1 m away everywhere: points hidden
  b.depth = wall;
  EXPECT_EQ(computeErrorResistance(a, b, paperGate()), kInfinity);
  // A surface at the points' depth in b (within 3 %) keeps them visible.
  auto same = std::make_shared<DepthMap>(*wall);
  const double z = b.pose.worldToCamera(a.points.col(0)).z();
  same->depth.assign(80 * 60, static_cast<float>(z * 1.02));
  b.depth = same;
  EXPECT_TRUE(std::isfinite(computeErrorResistance(a, b, paperGate())));
  // Unknown depth (0) cannot occlude.
  auto unknown = std::make_shared<DepthMap>(*wall);
  unknown->depth.assign(80 * 60, 0.0f);
  b.depth = unknown;
  EXPECT_TRUE(std::isfinite(computeErrorResistance(a, b, paperGate())));
}

// The lookup is defined for any pixel and any consistent map (a state file may hold odd cells).
TEST(ErrorResistanceMatrix, DepthMapLookupIsDefinedForAnyPixel) {
  DepthMap map;
  map.cols = 4;
  map.rows = 3;
  map.cell_width = map.cell_height = 8.0;
  map.depth.assign(12, 2.0f);
  map.depth[2 * 4 + 3] = 5.0f;
  EXPECT_EQ(map.at(31.9, 23.9), 5.0f);
  EXPECT_EQ(map.at(0.0, 0.0), 2.0f);
  EXPECT_EQ(map.at(32.0, 0.0), 0.0f);
  EXPECT_EQ(map.at(-0.5, 0.0), 0.0f);
  EXPECT_EQ(map.at(0.0, 1e300), 0.0f);
  EXPECT_EQ(map.at(std::nan(""), 1.0), 0.0f);
  EXPECT_EQ(map.at(1.0, std::numeric_limits<double>::infinity()), 0.0f);
  map.cell_width = map.cell_height = 1e-256;  // positive and finite: consistent, and tiny
  ASSERT_TRUE(map.isConsistent());
  EXPECT_EQ(map.at(100.0, 100.0), 0.0f);
  EXPECT_EQ(map.at(0.0, 0.0), 2.0f);
}

TEST(ErrorResistanceMatrix, ViewAngleGateAndDiagonal) {
  auto [a, b] = twoViews(30);
  const double angle = std::acos(a.pose.opticalAxis().dot(b.pose.opticalAxis())) * 180.0 / M_PI;
  ErrorResistanceConfig config = paperGate();
  config.gate = Gate::kMatchable;  // the paper's preset would switch the view-angle gate off
  config.max_parallax_deg = 0.0;
  config.max_scale_ratio = 0.0;
  config.min_covisible_ratio = 0.1;
  config.max_view_angle_deg = angle + 0.5;
  EXPECT_TRUE(std::isfinite(computeErrorResistance(a, b, config)));
  config.max_view_angle_deg = angle - 0.5;
  EXPECT_EQ(computeErrorResistance(a, b, config), kInfinity);

  ErrorResistanceMatrix matrix(paperGate());
  matrix.addKeyframe(a);
  matrix.addKeyframe(b);
  EXPECT_EQ(matrix.at(0, 0), kInfinity);
  EXPECT_EQ(matrix.at(1, 1), kInfinity);
  EXPECT_TRUE(std::isfinite(matrix.at(0, 1)));
  EXPECT_EQ(matrix.at(1, 0), kInfinity);  // b has no points
}

TEST(ErrorResistanceMatrix, MedianOfEvenCountIsMeanOfMiddleValues) {
  auto [a, b] = twoViews(12);
  std::vector<double> r;
  for (int q = 0; q < 12; ++q)
    r.push_back(pointErrorResistance(a.points.col(q), a.pose.position, b.intrinsics, b.pose));
  std::sort(r.begin(), r.end());
  ASSERT_LT(r[5], r[6]);  // distinct middle values, so the rule matters
  EXPECT_DOUBLE_EQ(computeErrorResistance(a, b, paperGate()), 0.5 * (r[5] + r[6]));
}

TEST(ErrorResistanceMatrix, RejectsUnusableKeyframesAndKeepsState) {
  auto [a, b] = twoViews(20);
  ErrorResistanceMatrix matrix;
  matrix.addKeyframe(a);
  Keyframe bad = b;
  bad.pose.position.x() = std::nan("");
  EXPECT_THROW(matrix.addKeyframe(bad), InvalidInput);
  bad = b;
  bad.intrinsics.fx = 0.0;
  EXPECT_THROW(matrix.addKeyframe(bad), InvalidInput);
  bad = b;
  bad.pose.orientation = Eigen::Quaterniond(0, 0, 0, 0);
  EXPECT_THROW(matrix.addKeyframe(bad), InvalidInput);
  EXPECT_EQ(matrix.size(), 1u);
  EXPECT_EQ(matrix.addKeyframe(b), 1);
  ErrorResistanceConfig no_points;
  no_points.min_covisible_points = 0;
  EXPECT_THROW(ErrorResistanceMatrix{no_points}, InvalidArgument);
}

}  // namespace
}  // namespace view_selection
