// The points-only corridor walk (generate_sequence --points-only) and its points.bin: records
// read back as written (float-rounded points, exact poses and stamps), the same seed gives the
// same bytes, every keyframe's points lie on the corridor's surfaces within range, and a damaged
// file is an error naming it.
#include "view_selection/core/exceptions.h"
#include "view_selection/io/points_file.h"
#include "view_selection/sim/corridor_walk.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace fs = std::filesystem;
using namespace view_selection;

namespace {

fs::path scratch(const std::string& name) {
  return fs::temp_directory_path() /
         ("view_selection_corridor_" + std::to_string(::getpid()) + "_" + name);
}

std::string bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(CorridorWalk, PointsBinReadsBackWhatWasWritten) {
  sim::CorridorWalkConfig c;
  c.frames = 120;
  c.seed = 7;
  const fs::path dir = scratch("a");
  sim::writeCorridorWalk(dir.string(), c);
  for (const char* f : {"points.bin", "groundtruth.txt", "camera.yaml", "SOURCE.md"})
    EXPECT_TRUE(fs::exists(dir / f)) << f;
  io::PointsFileReader reader((dir / "points.bin").string());
  ASSERT_EQ(reader.size(), 120u);
  EXPECT_EQ(reader.intrinsics().fx, c.intrinsics.fx);
  EXPECT_EQ(reader.intrinsics().width, c.intrinsics.width);
  io::PointsRecord r;
  for (int i = 0; i < c.frames; ++i) {
    ASSERT_TRUE(reader.next(r)) << i;
    const io::PointsRecord want = sim::corridorKeyframe(c, i);
    EXPECT_EQ(r.stamp, want.stamp);
    EXPECT_EQ(r.pose.position, want.pose.position);
    EXPECT_EQ(r.pose.orientation.coeffs(), want.pose.orientation.coeffs());
    ASSERT_EQ(r.points.cols(), want.points.cols());
    EXPECT_EQ(r.points, want.points.cast<float>().cast<double>()) << "keyframe " << i;
    // On a wall, the floor or the ceiling, within range, in front of the camera.
    EXPECT_EQ(r.points.cols(), c.points) << "keyframe " << i << " got too few points";
    const Eigen::Matrix3d R = want.pose.rotation();
    for (Eigen::Index q = 0; q < want.points.cols(); ++q) {
      const Eigen::Vector3d p = want.points.col(q);
      const double wall = std::min(std::abs(std::abs(p.x()) - 0.5 * c.width),
                                   std::abs(std::abs(p.y()) - 0.5 * c.height));
      EXPECT_LT(wall, 1e-9) << "keyframe " << i << " point " << q << " is on no surface";
      EXPECT_LE((p - want.pose.position).norm(), c.max_range + 1e-9);
      EXPECT_GT((R.transpose() * (p - want.pose.position)).z(), 0.0);
    }
  }
  EXPECT_FALSE(reader.next(r));
  // Deterministic: the same seed, the same bytes; another seed, other points.
  const fs::path again = scratch("b");
  sim::writeCorridorWalk(again.string(), c);
  EXPECT_TRUE(bytes(dir / "points.bin") == bytes(again / "points.bin"));
  c.seed = 8;
  sim::writeCorridorWalk(again.string(), c);
  EXPECT_FALSE(bytes(dir / "points.bin") == bytes(again / "points.bin"));
  fs::remove_all(again);

  // Truncated: an error that names the file, not a short read taken as the end.
  fs::resize_file(dir / "points.bin", fs::file_size(dir / "points.bin") - 100);
  io::PointsFileReader truncated((dir / "points.bin").string());
  try {
    while (truncated.next(r)) {
    }
    ADD_FAILURE() << "a truncated points.bin read to the end";
  } catch (const core::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("points.bin"), std::string::npos) << e.what();
  }
  std::ofstream(dir / "points.bin", std::ios::binary) << "not points";
  EXPECT_THROW(io::PointsFileReader((dir / "points.bin").string()), core::InvalidInput);
  fs::remove_all(dir);
}

}  // namespace
