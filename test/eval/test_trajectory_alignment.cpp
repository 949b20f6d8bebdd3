// Sim(3) Umeyama alignment and ATE: known similarities recovered, degenerate input refused.
#include "view_selection/core/exceptions.h"
#include "view_selection/eval/trajectory_alignment.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include "support/layers.h"

namespace view_selection {
namespace {

Eigen::Matrix3Xd randomPoints(std::mt19937& rng, int n, double spread = 2.0) {
  std::uniform_real_distribution<double> u(-spread, spread);
  Eigen::Matrix3Xd p(3, n);
  for (int i = 0; i < n; ++i) {
    // One draw at a time, z first: the order gcc evaluated Vector3d(u(rng), ...) in before
    // (argument order is unspecified; clang's differs).
    const double z = u(rng), y = u(rng), x = u(rng);
    p.col(i) = Eigen::Vector3d(x, y, z);
  }
  return p;
}

SimilarityTransform knownTransform() {
  SimilarityTransform t;
  t.scale = 3.7;
  t.rotation =
      Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()).toRotationMatrix();
  t.translation = Eigen::Vector3d(10.0, -4.0, 2.5);
  return t;
}

Eigen::Matrix3Xd applyTo(const SimilarityTransform& t, const Eigen::Matrix3Xd& p) {
  Eigen::Matrix3Xd q(3, p.cols());
  for (Eigen::Index i = 0; i < p.cols(); ++i) q.col(i) = t.apply(p.col(i));
  return q;
}

TEST(TrajectoryAlignment, RecoversKnownSimilarityExactly) {
  std::mt19937 rng(7);
  const Eigen::Matrix3Xd est = randomPoints(rng, 40);
  const SimilarityTransform truth = knownTransform();
  const TrajectoryError r = absoluteTrajectoryError(est, applyTo(truth, est));
  EXPECT_NEAR(r.alignment.scale, truth.scale, 1e-9);
  EXPECT_LT((r.alignment.rotation - truth.rotation).norm(), 1e-9);
  EXPECT_LT((r.alignment.translation - truth.translation).norm(), 1e-8);
  EXPECT_NEAR(r.alignment.rotation.determinant(), 1.0, 1e-12);
  EXPECT_LT(r.rmse, 1e-8);
  EXPECT_LT(r.max, 1e-8);
  EXPECT_EQ(r.count, 40u);
}

TEST(TrajectoryAlignment, PlanarPointsAreEnough) {
  // A camera path in a plane (a common trajectory) still fixes the similarity.
  Eigen::Matrix3Xd est(3, 5);
  est << 0, 1, 2, 0, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0;
  const SimilarityTransform truth = knownTransform();
  const TrajectoryError r = absoluteTrajectoryError(est, applyTo(truth, est));
  EXPECT_NEAR(r.alignment.scale, truth.scale, 1e-9);
  EXPECT_LT((r.alignment.rotation - truth.rotation).norm(), 1e-9);
  EXPECT_LT(r.rmse, 1e-9);
}

TEST(TrajectoryAlignment, NoisyPointsGiveCloseTransformAndErrorOfNoiseSize) {
  std::mt19937 rng(11);
  const Eigen::Matrix3Xd est = randomPoints(rng, 500);
  const SimilarityTransform truth = knownTransform();
  Eigen::Matrix3Xd gt = applyTo(truth, est);
  const double sigma = 0.05;  // per axis, ground-truth units
  std::normal_distribution<double> noise(0.0, sigma);
  for (Eigen::Index i = 0; i < gt.cols(); ++i) {
    const double z = noise(rng), y = noise(rng), x = noise(rng);  // z first, as above
    gt.col(i) += Eigen::Vector3d(x, y, z);
  }
  const TrajectoryError r = absoluteTrajectoryError(est, gt);
  EXPECT_NEAR(r.alignment.scale, truth.scale, 0.01);
  EXPECT_LT(Eigen::AngleAxisd(r.alignment.rotation.transpose() * truth.rotation).angle(), 0.005);
  // RMSE of isotropic 3D noise is sigma*sqrt(3), less the little the fit absorbs.
  EXPECT_NEAR(r.rmse, sigma * std::sqrt(3.0), 0.1 * sigma * std::sqrt(3.0));
  EXPECT_LE(r.median, r.max);
  EXPECT_LE(r.mean, r.rmse);
  EXPECT_GT(r.mean, 0.0);
}

TEST(TrajectoryAlignment, StatisticsOnAHandWorkedCase) {
  // Identity alignment is optimal when the residuals are symmetric about zero: two points off by
  // +/-1 in z around a square keep the fit at identity.
  Eigen::Matrix3Xd est(3, 4), gt(3, 4);
  est << 0, 1, 0, 1, 0, 0, 1, 1, 0, 0, 0, 0;
  gt = est;
  gt(2, 0) = 0.5;
  gt(2, 3) = -0.5;
  AlignmentConfig no_scale;
  no_scale.with_scale = false;
  const TrajectoryError r = absoluteTrajectoryError(est, gt, no_scale);
  EXPECT_DOUBLE_EQ(r.alignment.scale, 1.0);
  ASSERT_EQ(r.errors.size(), 4u);
  // Whatever the fit, the statistics must be consistent with the residuals it reports.
  double sum = 0, sq = 0, mx = 0;
  for (double e : r.errors) sum += e, sq += e * e, mx = std::max(mx, e);
  EXPECT_NEAR(r.mean, sum / 4, 1e-12);
  EXPECT_NEAR(r.rmse, std::sqrt(sq / 4), 1e-12);
  EXPECT_NEAR(r.max, mx, 1e-12);
  std::vector<double> s = r.errors;
  std::sort(s.begin(), s.end());
  EXPECT_NEAR(r.median, 0.5 * (s[1] + s[2]), 1e-12);
  EXPECT_LT(r.rmse, 0.5);  // a rotation absorbs part of the tilt
}

TEST(TrajectoryAlignment, DegenerateInputIsRefusedWithAReason) {
  Eigen::Matrix3Xd two(3, 2);
  two << 0, 1, 0, 0, 0, 0;
  try {
    alignUmeyama(two, two);
    FAIL() << "two points accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("at least 3"), std::string::npos) << e.what();
  }
  Eigen::Matrix3Xd line(3, 6);
  for (int i = 0; i < 6; ++i) line.col(i) = Eigen::Vector3d(1, 2, 3) * i + Eigen::Vector3d(5, 0, 0);
  try {
    alignUmeyama(line, line);
    FAIL() << "collinear points accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("collinear"), std::string::npos) << e.what();
  }
  Eigen::Matrix3Xd same = Eigen::Matrix3Xd::Ones(3, 4);
  EXPECT_THROW(alignUmeyama(same, same), InvalidArgument);
  Eigen::Matrix3Xd three(3, 3);
  three << 0, 1, 0, 0, 0, 1, 0, 0, 0;
  EXPECT_THROW(alignUmeyama(three, Eigen::Matrix3Xd(three.leftCols(2))), InvalidArgument);
  Eigen::Matrix3Xd bad = three;
  bad(0, 0) = std::nan("");
  EXPECT_THROW(alignUmeyama(bad, three), InvalidArgument);
}

TEST(TrajectoryAlignment, ReadsColmapImagesTxtCentres) {
  const auto path = std::filesystem::temp_directory_path() / "view_selection_test_images.txt";
  {
    std::ofstream f(path);
    f << "# Image list with two lines of data per image:\n"
         "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
         "# Number of images: 2, mean observations per image: 1\n"
         "1 1 0 0 0 1 2 3 1 a.jpg\n"
         "10.0 20.0 -1\n"
         // 90 degrees about z: R = [[0,-1,0],[1,0,0],[0,0,1]], centre = -R^T t
         "2 0.7071067811865476 0 0 0.7071067811865476 1 0 0 1 b c.jpg\n"
         "\n";
  }
  const auto images = readColmapImagesTxt(path.string());
  ASSERT_EQ(images.size(), 2u);
  EXPECT_EQ(images[0].name, "a.jpg");
  EXPECT_LT((images[0].centre - Eigen::Vector3d(-1, -2, -3)).norm(), 1e-12);
  EXPECT_EQ(images[1].image_id, 2);
  EXPECT_EQ(images[1].name, "b c.jpg");
  EXPECT_LT((images[1].centre - Eigen::Vector3d(0, 1, 0)).norm(), 1e-9);

  {
    std::ofstream f(path);
    f << "1 1 0 0 x 1 2 3 1 a.jpg\n\n";
  }
  try {
    readColmapImagesTxt(path.string());
    FAIL() << "malformed line accepted";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find(":1:"), std::string::npos) << e.what();
  }
  std::filesystem::remove(path);
  EXPECT_THROW(readColmapImagesTxt(path.string()), IoError);
}

}  // namespace
}  // namespace view_selection
