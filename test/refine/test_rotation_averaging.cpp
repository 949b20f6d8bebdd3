// The rotations' global start (rotation_averaging.h): a loop of cameras whose odometry's heading
// drifted by a right angle, its consecutive relative rotations and its revisits' (noisy, a few
// of them wrong) averaged back to the true orientations; the pair rotations file.
#include "view_selection/core/exceptions.h"
#include "view_selection/refine/rotation_averaging.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

namespace {

using namespace view_selection;
namespace fs = std::filesystem;

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

double angleDeg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return a.angularDistance(b) / kDeg;
}

Eigen::Quaterniond turned(std::mt19937& rng, double sigma_deg) {
  std::normal_distribution<double> n(0.0, 1.0);
  const Eigen::Vector3d axis = Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
  return Eigen::Quaterniond(Eigen::AngleAxisd(sigma_deg * kDeg * n(rng), axis));
}

/// 120 cameras walking round a room twice (world to camera, each looking outwards, tilted a
/// little), ids 1..120.
std::map<int, Eigen::Quaterniond> walk() {
  std::map<int, Eigen::Quaterniond> r;
  for (int i = 0; i < 120; ++i) {
    const double heading = 2.0 * kPi * (i % 60) / 60.0;
    const Eigen::Matrix3d c2w =
        (Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(0.1 * std::sin(0.3 * i), Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
    r[i + 1] = Eigen::Quaterniond(c2w.transpose());
  }
  return r;
}

struct Drifted {
  std::map<int, Eigen::Quaterniond> odometry;  ///< the start: heading drifted 0.8 degrees a step
  std::vector<refine::RelativeRotation> relatives;  ///< consecutive (odometry) and revisits (pairs)
};

Drifted drifted(const std::map<int, Eigen::Quaterniond>& exact, std::mt19937& rng,
                int wrong_pairs) {
  Drifted d;
  const Eigen::Quaterniond step_drift(Eigen::AngleAxisd(0.8 * kDeg, Eigen::Vector3d::UnitY()));
  Eigen::Quaterniond accumulated = Eigen::Quaterniond::Identity();
  for (const auto& [id, q] : exact) {
    // The world turned under the camera: c2w' = D c2w, so w2c' = w2c D^T.
    d.odometry[id] = (q * accumulated.conjugate()).normalized();
    accumulated = step_drift * turned(rng, 0.1) * accumulated;
  }
  for (int i = 1; i < 120; ++i)  // the odometry's own relative rotations, as the priors have them
    d.relatives.push_back(
        {i, i + 1, (d.odometry.at(i + 1) * d.odometry.at(i).conjugate()).normalized(), 3.0 * kDeg});
  int wrong = 0;
  for (int i = 1; i <= 60; ++i)
    for (int j : {i + 60, i + 59, i + 61}) {  // the second lap revisits the first
      if (j < 1 || j > 120) continue;
      Eigen::Quaterniond r =
          (exact.at(j) * exact.at(i).conjugate() * turned(rng, 2.0)).normalized();
      if (wrong < wrong_pairs && i % 7 == 0) {  // a pair verified with a wrong geometry
        r = (Eigen::Quaterniond(Eigen::AngleAxisd(70.0 * kDeg, Eigen::Vector3d::UnitZ())) * r)
                .normalized();
        ++wrong;
      }
      d.relatives.push_back({i, j, r, 5.0 * kDeg});
    }
  for (int i = 1; i + 3 <= 120; i += 2)  // neighbours a few keyframes apart
    d.relatives.push_back(
        {i, i + 3, (exact.at(i + 3) * exact.at(i).conjugate() * turned(rng, 2.0)).normalized(),
         5.0 * kDeg});
  return d;
}

/// The largest angle [deg] between `a` and `exact` once a's frame is turned onto exact's at `held`.
double largestError(const std::map<int, Eigen::Quaterniond>& a,
                    const std::map<int, Eigen::Quaterniond>& exact, int held) {
  const Eigen::Quaterniond frame =
      a.at(held).conjugate() * exact.at(held);  // w2c_a frame = w2c_exact
  double worst = 0.0;
  for (const auto& [id, q] : exact) worst = std::max(worst, angleDeg(a.at(id) * frame, q));
  return worst;
}

TEST(RotationAveraging, TurnsADriftedHeadingBackWithTheRevisitsAndDiscountsWrongPairs) {
  std::mt19937 rng(34);
  const auto exact = walk();
  const Drifted d = drifted(exact, rng, 5);
  ASSERT_GT(largestError(d.odometry, exact, 1), 80.0);  // 0.8 degrees a step over 120 steps
  const refine::RotationAveragingResult r =
      refine::averageRotations(d.odometry, d.relatives, 1, 10);
  ASSERT_TRUE(r.solved);
  EXPECT_GT(r.iterations, 1);
  EXPECT_EQ(d.odometry.size(), r.rotations.size());
  EXPECT_NEAR(0.0, angleDeg(r.rotations.at(1), d.odometry.at(1)), 1e-9);  // the held image's stays
  EXPECT_LT(largestError(r.rotations, exact, 1), 4.0);
  // One solve, no reweighting: the wrong pairs pull it further off.
  const refine::RotationAveragingResult once =
      refine::averageRotations(d.odometry, d.relatives, 1, 1);
  EXPECT_GT(largestError(once.rotations, exact, 1), largestError(r.rotations, exact, 1));
}

TEST(RotationAveraging, ImagesNotConnectedToTheHeldOneKeepTheirStart) {
  std::mt19937 rng(7);
  const auto exact = walk();
  Drifted d = drifted(exact, rng, 0);
  std::map<int, Eigen::Quaterniond> start = d.odometry;
  start[500] = turned(rng, 40.0);  // an image no relative rotation names
  start[501] = turned(rng, 40.0);
  const Eigen::Quaterniond r501 = (start.at(501) * start.at(500).conjugate()).normalized();
  d.relatives.push_back({500, 501, r501, 5.0 * kDeg});  // ... and a pair apart from the rest
  d.relatives.push_back(
      {1, 999, Eigen::Quaterniond::Identity(), 5.0 * kDeg});  // an unknown image: left out
  const refine::RotationAveragingResult r = refine::averageRotations(start, d.relatives, 1, 10);
  ASSERT_TRUE(r.solved);
  EXPECT_FALSE(r.rotations.count(999));
  EXPECT_LT(angleDeg(r.rotations.at(500), start.at(500)), 1e-3);
  EXPECT_LT(angleDeg(r.rotations.at(501), start.at(501)), 1e-3);
  // Without any relative rotation, or without the held image, the start comes back unsolved.
  EXPECT_FALSE(refine::averageRotations(start, {}, 1, 10).solved);
  EXPECT_FALSE(refine::averageRotations(start, d.relatives, 12345, 10).solved);
}

TEST(PairRotations, FilesReadBackAndBrokenOnesAreRefused) {
  const fs::path dir = fs::temp_directory_path() / ("vs_rotations_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::mt19937 rng(3);
  std::vector<refine::PairRotation> written;
  for (int k = 0; k < 5; ++k) written.push_back({k + 1, k + 7, turned(rng, 30.0).normalized()});
  const std::string path = (dir / "rotations.bin").string();
  refine::writePairRotations(path, written);
  const auto read = refine::readPairRotations(path);
  ASSERT_EQ(written.size(), read.size());
  for (size_t k = 0; k < read.size(); ++k) {
    EXPECT_EQ(written[k].a, read[k].a);
    EXPECT_EQ(written[k].b, read[k].b);
    EXPECT_TRUE(written[k].rotation_ba.coeffs().isApprox(read[k].rotation_ba.coeffs(), 1e-15));
  }
  {  // a count its bytes do not hold
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(8);
    const uint64_t count = 6;
    f.write(reinterpret_cast<const char*>(&count), 8);
  }
  EXPECT_THROW(refine::readPairRotations(path), core::IoError);
  refine::writePairRotations(path,
                             {{1, 2, Eigen::Quaterniond(0.0, 0.0, 0.0, 0.0)}});  // COLMAP's "none"
  EXPECT_THROW(refine::readPairRotations(path), core::IoError);
  std::ofstream(path, std::ios::binary) << "VSMATCH1";
  EXPECT_THROW(refine::readPairRotations(path), core::IoError);
  EXPECT_THROW(refine::readPairRotations((dir / "missing.bin").string()), core::IoError);
  fs::remove_all(dir);
}

}  // namespace
