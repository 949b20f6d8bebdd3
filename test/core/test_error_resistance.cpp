// r(P; i -> j): the closed form against brute-force re-triangulation, the shape of the curve,
// and the +inf cases of METHOD.md.
#include "view_selection/core/error_resistance.h"

#include "support/test_support.h"

#include <gtest/gtest.h>

#include <cstring>
#include <vector>

#include <cmath>
#include <random>
#include <vector>
#include "support/layers.h"
#include "view_selection/eval/reference_error_resistance.h"

namespace view_selection {
namespace {

using test::lookAt;
using test::vgaIntrinsics;

struct RandomPair {
  Eigen::Vector3d point;
  PinholeIntrinsics k_i, k_j;
  CameraPose pose_i, pose_j;
};

/// Well-conditioned: parallax 10-150 deg, distances 0.5-8, P within the image of both views.
RandomPair randomPair(std::mt19937& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  RandomPair c;
  c.point = 10.0 * test::drawnVector3(rng, uni) - Eigen::Vector3d::Constant(5.0);
  const Eigen::Vector3d v1 = test::randomUnit(rng);
  const Eigen::Vector3d axis = v1.cross(test::randomUnit(rng)).normalized();
  const double parallax = (10.0 + 140.0 * uni(rng)) * M_PI / 180.0;
  const Eigen::Vector3d v2 = Eigen::AngleAxisd(parallax, axis) * v1;
  const Eigen::Vector3d o_i = c.point + (0.5 + 7.5 * uni(rng)) * v1;
  const Eigen::Vector3d o_j = c.point + (0.5 + 7.5 * uni(rng)) * v2;
  auto jitter = [&](double scale) { return scale * (2.0 * uni(rng) - 1.0); };
  const double dist_i = (o_i - c.point).norm();
  const double dist_j = (o_j - c.point).norm();
  c.pose_i = lookAt(o_i, c.point + Eigen::Vector3d(jitter(0.1), jitter(0.1), jitter(0.1)) * dist_i,
                    jitter(M_PI));
  c.pose_j = lookAt(o_j, c.point + Eigen::Vector3d(jitter(0.1), jitter(0.1), jitter(0.1)) * dist_j,
                    jitter(M_PI));
  c.k_i = vgaIntrinsics(300.0 + 900.0 * uni(rng));
  c.k_j = vgaIntrinsics(300.0 + 900.0 * uni(rng));
  c.k_j.fy = c.k_j.fx * (0.95 + 0.1 * uni(rng));  // non-square pixels
  c.k_j.cx += jitter(20.0);
  return c;
}

TEST(ErrorResistance, ClosedFormMatchesBruteForceTriangulation) {
  std::mt19937 rng(20240611);
  int compared = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const RandomPair c = randomPair(rng);
    const double closed = pointErrorResistance(c.point, c.pose_i.position, c.k_j, c.pose_j);
    const double brute =
        pointErrorResistanceByTriangulation(c.point, c.k_i, c.pose_i, c.k_j, c.pose_j);
    ASSERT_TRUE(std::isfinite(closed)) << "trial " << trial;
    ASSERT_TRUE(std::isfinite(brute)) << "trial " << trial;
    ASSERT_GT(closed, 0.0);
    EXPECT_NEAR(closed, brute, 1e-6 * brute) << "trial " << trial;
    const double sine_law =
        pointErrorResistanceSineLaw(c.point, c.pose_i.position, c.k_j, c.pose_j);
    EXPECT_NEAR(sine_law, brute, 1e-6 * brute) << "trial " << trial;
    ++compared;
  }
  EXPECT_EQ(compared, 3000);
}

TEST(ErrorResistance, BatchedEqualsOnePointAtATimeToTheLastBit) {
  // The batched form feeds the matrix; it must give operator()'s values exactly (the paper's
  // gate is held bit for bit against earlier output), on good points and on every way a point
  // can fail: behind j, on the baseline, beyond the rays' meeting, NaN.
  std::mt19937 rng(77);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  size_t finite = 0, infinite = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const RandomPair c = randomPair(rng);
    const PairErrorResistance pair(c.pose_i.position, c.k_j, c.pose_j);
    std::vector<double> x, y, z;
    for (int q = 0; q < 257; ++q) {  // not a multiple of any vector width
      Eigen::Vector3d p = c.pose_j.worldToCamera(c.point + Eigen::Vector3d(uni(rng) - 0.5, uni(rng) - 0.5, uni(rng) - 0.5));
      if (q % 17 == 3) p.z() = -p.z();                     // behind camera j
      if (q % 31 == 5) p = 0.5 * pair.originICam();        // on the baseline
      if (q % 61 == 7) p.x() = std::nan("");
      if (q % 43 == 9) p = 40.0 * pair.originICam() + Eigen::Vector3d(0.01, 0.0, 0.0);  // little parallax
      x.push_back(p.x());
      y.push_back(p.y());
      z.push_back(p.z());
    }
    std::vector<double> out(x.size());
    pair.evaluate(x.data(), y.data(), z.data(), x.size(), out.data());
    for (size_t q = 0; q < x.size(); ++q) {
      const double one = pair(Eigen::Vector3d(x[q], y[q], z[q]));
      ASSERT_EQ(std::memcmp(&one, &out[q], sizeof(double)), 0)
          << "trial " << trial << " point " << q << ": " << one << " vs " << out[q];
      (std::isfinite(one) ? finite : infinite) += 1;
    }
  }
  EXPECT_GT(finite, 10000u);
  EXPECT_GT(infinite, 1000u);
}

TEST(ErrorResistance, EpipoleAtInfinityUsesTheProjectedBaseline) {
  // Parallel cameras, pure sideways translation: O_i lies in camera j's z = 0 plane.
  const PinholeIntrinsics k = vgaIntrinsics(500.0);
  CameraPose pose_i, pose_j;
  pose_i.position = Eigen::Vector3d(0.0, 0.0, 0.0);
  pose_j.position = Eigen::Vector3d(0.4, 0.1, 0.0);
  for (const Eigen::Vector3d& p :
       {Eigen::Vector3d(0.2, 0.05, 2.0), Eigen::Vector3d(-0.3, 0.4, 3.0)}) {
    const Eigen::Vector3d epipole = k.matrix() * pose_j.worldToCamera(pose_i.position);
    ASSERT_EQ(epipole.z(), 0.0);
    const double closed = pointErrorResistance(p, pose_i.position, k, pose_j);
    const double brute = pointErrorResistanceByTriangulation(p, k, pose_i, k, pose_j);
    ASSERT_TRUE(std::isfinite(closed));
    EXPECT_NEAR(closed, brute, 1e-6 * brute);
    EXPECT_NEAR(pointErrorResistanceSineLaw(p, pose_i.position, k, pose_j), brute, 1e-6 * brute);
    // Fronto-parallel stereo: disparity along the baseline is f b / z; one pixel less moves the
    // depth to f b / (f b / z - 1), and P slides along its ray from O_i by |P| / (f b / z - 1).
    const double b = std::hypot(0.4, 0.1);
    const double expected = p.norm() / (500.0 * b / p.z() - 1.0);
    EXPECT_NEAR(closed, expected, 1e-6 * expected);
  }
}

TEST(ErrorResistance, EpipolarDirectionIsAlongTheLineToTheEpipole) {
  const Eigen::Vector2d p(100.0, 50.0);
  const Eigen::Vector3d epipole_h(2.0 * 400.0, 2.0 * 250.0, 2.0);  // finite epipole (400, 250)
  const auto u = epipolarDirection(epipole_h, p);
  ASSERT_TRUE(u.has_value());
  const Eigen::Vector2d to_epipole = (Eigen::Vector2d(400.0, 250.0) - p).normalized();
  EXPECT_NEAR(std::abs(u->dot(to_epipole)), 1.0, 1e-12);
  EXPECT_FALSE(epipolarDirection(epipole_h, Eigen::Vector2d(400.0, 250.0)).has_value());
}

TEST(ErrorResistance, InfiniteWhenBehindCameraOnBaselineOrWithoutParallax) {
  const PinholeIntrinsics k = vgaIntrinsics();
  const CameraPose pose_i = lookAt({0, 0, 0}, {0, 0, 1});
  const CameraPose pose_j = lookAt({0.5, 0, 0}, {0.5, 0, 1});
  // Behind camera j.
  EXPECT_EQ(pointErrorResistance({0.2, 0.0, -2.0}, pose_i.position, k, pose_j), kInfinity);
  // On the baseline: the point, O_i and O_j are collinear.
  const CameraPose pose_j_ahead = lookAt({0, 0, -1}, {0, 0, 1});
  EXPECT_EQ(pointErrorResistance({0.0, 0.0, 3.0}, pose_i.position, k, pose_j_ahead), kInfinity);
  // Parallax far below one pixel: the moved ray turning away never meets the ray from O_i.
  const CameraPose pose_j_tiny = lookAt({1e-6, 0, 0}, {1e-6, 0, 1});
  EXPECT_EQ(pointErrorResistance({0.0, 0.0, 3.0}, pose_i.position, k, pose_j_tiny), kInfinity);
  EXPECT_EQ(pointErrorResistanceSineLaw({0.0, 0.0, 3.0}, pose_i.position, k, pose_j_tiny),
            kInfinity);
  EXPECT_EQ(pointErrorResistanceSineLaw({0.2, 0.0, -2.0}, pose_i.position, k, pose_j), kInfinity);
  // A sane configuration is finite and positive.
  const double r = pointErrorResistance({0.25, 0.0, 2.0}, pose_i.position, k, pose_j);
  EXPECT_TRUE(std::isfinite(r));
  EXPECT_GT(r, 0.0);
}

TEST(ErrorResistance, IsDirectional) {
  const PinholeIntrinsics k = vgaIntrinsics();
  const Eigen::Vector3d p(0.1, 0.0, 3.0);
  const CameraPose a = lookAt({0, 0, 0}, p);
  const CameraPose b = lookAt({1.5, 0.2, 0.5}, p);
  const double ab = pointErrorResistance(p, a.position, k, b);
  const double ba = pointErrorResistance(p, b.position, k, a);
  ASSERT_TRUE(std::isfinite(ab) && std::isfinite(ba));
  // Different distances to P: the displacement is measured along different rays.
  EXPECT_GT(std::abs(ab - ba), 1e-3 * std::min(ab, ba));
}

TEST(ErrorResistance, CurveFallsSteeplyHasMinimumThenRisesSlowly) {
  // Camera i fixed; camera j orbits P at the same distance, always looking at P. Parallax is the
  // orbit angle. METHOD.md: steep fall, minimum near 60-90 deg, slow rise.
  const PinholeIntrinsics k = vgaIntrinsics();
  const Eigen::Vector3d p(0.0, 0.0, 3.0);
  const CameraPose pose_i = lookAt({0, 0, 0}, p);
  std::vector<double> angles, values;
  for (double deg = 1.0; deg <= 170.0; deg += 1.0) {
    const double a = deg * M_PI / 180.0;
    const Eigen::Vector3d o_j = p + 3.0 * Eigen::Vector3d(std::sin(a), 0.0, -std::cos(a));
    const CameraPose pose_j = lookAt(o_j, p, 0.3);
    angles.push_back(deg);
    values.push_back(pointErrorResistance(p, pose_i.position, k, pose_j));
    ASSERT_TRUE(std::isfinite(values.back())) << deg;
  }
  const size_t best =
      static_cast<size_t>(std::min_element(values.begin(), values.end()) - values.begin());
  EXPECT_GE(angles[best], 60.0);
  EXPECT_LE(angles[best], 92.0);
  for (size_t q = 1; q <= best; ++q) EXPECT_LT(values[q], values[q - 1]) << angles[q];
  for (size_t q = best + 1; q < values.size(); ++q)
    EXPECT_GT(values[q], values[q - 1]) << angles[q];
  // Steep: 1 deg of parallax is far worse than 10 deg; slow: 150 deg is within 2.5x of the best.
  EXPECT_GT(values[0] / values[9], 8.0);
  EXPECT_GT(values[9] / values[best], 5.0);
  const size_t at150 = 149;
  EXPECT_LT(values[at150] / values[best], 2.5);
}

}  // namespace
}  // namespace view_selection
