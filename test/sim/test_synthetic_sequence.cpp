// The built-in synthetic sequence: determinism, exact geometry (ray casting, distance to the
// surface, depth against poses), the TUM folder and its writers read back by the repo's reader,
// textures that features can match, the generate_sequence tool, and the method running on it.
#include "view_selection/sim/synthetic_sequence.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/io/tum_dataset.h"
#include "view_selection/io/tum_frames.h"

#include <gtest/gtest.h>
#include <opencv2/core/utility.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include "support/layers.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/points/point_source_factory.h"

namespace view_selection {
namespace {

namespace fs = std::filesystem;

constexpr double kUnitsPerMetre = 5000.0;
constexpr double kPi = 3.14159265358979323846;

/// A fresh temporary folder, removed at the end of the test.
class TempDir {
 public:
  TempDir() {
    std::string pattern = (fs::temp_directory_path() / "vs_synthetic_XXXXXX").string();
    if (mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

SyntheticSequenceConfig smallConfig(uint64_t seed = 7, int frames = 30) {
  SyntheticSequenceConfig c;
  c.seed = seed;
  c.frames = frames;
  c.intrinsics = syntheticIntrinsics(160, 120);
  return c;
}

std::string readBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// Every regular file under `root`, by relative path, with its bytes.
std::map<std::string, std::string> folderContents(const fs::path& root) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(root)) {
    if (entry.is_regular_file()) {
      files[fs::relative(entry.path(), root).string()] = readBytes(entry.path());
    }
  }
  return files;
}

double depthMetres(const cv::Mat& depth, int u, int v) {
  return depth.at<uint16_t>(v, u) / kUnitsPerMetre;
}

// ---------------------------------------------------------------------------------------------
// Scene geometry

TEST(SyntheticScene, LayoutIsInsideTheRoomAndObjectsAreApart) {
  const SyntheticScene scene(3);
  const auto& boxes = scene.boxes();
  ASSERT_GE(boxes.size(), 10u);  // room, table (top, 4 legs, box), wall objects
  EXPECT_TRUE(boxes[0].inside);
  EXPECT_EQ(boxes[0].name, "room");
  const Eigen::Vector3d half = scene.config().room_size / 2.0;
  for (size_t b = 1; b < boxes.size(); ++b) {
    EXPECT_FALSE(boxes[b].inside);
    // Every corner of every object lies inside the room.
    for (int corner = 0; corner < 8; ++corner) {
      Eigen::Vector3d local;
      for (int a = 0; a < 3; ++a) local[a] = ((corner >> a) & 1 ? 1 : -1) * boxes[b].half_size[a];
      const Eigen::Vector3d p =
          boxes[b].centre + Eigen::AngleAxisd(boxes[b].yaw, Eigen::Vector3d::UnitZ()) * local;
      EXPECT_LE(std::abs(p.x()), half.x() + 1e-9) << boxes[b].name;
      EXPECT_LE(std::abs(p.y()), half.y() + 1e-9) << boxes[b].name;
      EXPECT_GE(p.z(), -1e-9) << boxes[b].name;
      EXPECT_LE(p.z(), 2.0 * half.z() + 1e-9) << boxes[b].name;
    }
  }
}

TEST(SyntheticScene, CeilingDistanceAndRayAreExact) {
  const SyntheticScene scene(1);
  // Above the table, below the ceiling (3 m): the ceiling is the nearest surface, 0.5 m away.
  const Eigen::Vector3d p(0.0, 0.0, 2.5);
  EXPECT_NEAR(scene.distanceToSurface(p), 0.5, 1e-12);
  const auto up = scene.castRay(p, Eigen::Vector3d(0.0, 0.0, 2.0), 100.0);  // not unit length
  ASSERT_TRUE(up.has_value());
  EXPECT_NEAR(up->t, 0.25, 1e-12);  // t in units of the direction given
  EXPECT_EQ(up->box, 0);
  EXPECT_EQ(up->face, 5);
  EXPECT_NEAR((up->normal - Eigen::Vector3d(0, 0, -1)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((up->point - Eigen::Vector3d(0, 0, 3.0)).norm(), 0.0, 1e-12);
  EXPECT_FALSE(scene.castRay(p, Eigen::Vector3d(0.0, 0.0, 1.0), 0.4).has_value());  // max_t
  // Straight down from above the table: the first surface is the box on the table or the top.
  const auto down = scene.castRay(p, Eigen::Vector3d(0.0, 0.0, -1.0), 100.0);
  ASSERT_TRUE(down.has_value());
  EXPECT_NE(down->box, 0);
  EXPECT_GE(down->point.z(), 0.75 - 1e-9);
}

TEST(SyntheticScene, RayHitsLieOnSurfacesAndDistanceIsALowerBound) {
  const SyntheticScene scene(5);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(-2.9, 2.9), uy(-2.4, 2.4), uz(0.05, 2.95);
  std::normal_distribution<double> n(0.0, 1.0);
  int tested = 0;
  while (tested < 2000) {
    const double pz = uz(rng), py = uy(rng), px = ux(rng);  // last first, as gcc drew them
    const Eigen::Vector3d p(px, py, pz);
    if (!scene.isFree(p)) continue;
    ++tested;
    const double dz = n(rng), dy = n(rng), dx = n(rng);
    const Eigen::Vector3d d = Eigen::Vector3d(dx, dy, dz).normalized();
    const auto hit = scene.castRay(p, d, 100.0);
    ASSERT_TRUE(hit.has_value()) << "a closed room: every ray from inside hits";
    EXPECT_LT(scene.distanceToSurface(hit->point), 1e-9);
    // The nearest surface is no farther than the first one along any ray.
    EXPECT_LE(scene.distanceToSurface(p), hit->t + 1e-12);
    EXPECT_NEAR(hit->normal.norm(), 1.0, 1e-12);
    EXPECT_LT(hit->normal.dot(d), 0.0);  // faces the viewer
    // Stepping back along the normal: the surface is exactly that far, or something is nearer.
    const double step = 0.5 * scene.distanceToSurface(p);
    const Eigen::Vector3d q = hit->point + step * hit->normal;
    EXPECT_LE(scene.distanceToSurface(q), step + 1e-9);
    const auto back = scene.castRay(q, -hit->normal, 100.0);
    ASSERT_TRUE(back.has_value());
    EXPECT_LE(back->t, step + 1e-9);
  }
}

TEST(SyntheticScene, FreeSpaceAndCulling) {
  const SyntheticScene scene(2);
  EXPECT_FALSE(scene.isFree(Eigen::Vector3d(10.0, 0.0, 1.0)));      // outside the room
  EXPECT_FALSE(scene.isFree(Eigen::Vector3d(0.0, 0.0, 1.0), 0.6));  // within 0.6 m of the table
  const SceneBox& top = scene.boxes()[1];
  ASSERT_EQ(top.name, "table top");
  EXPECT_FALSE(scene.isFree(top.centre));  // inside an object
  // Culling never drops a box a ray would hit: rendering with and without it agree.
  SyntheticSequence sequence(smallConfig(2, 20));
  const PinholeIntrinsics& k = sequence.config().intrinsics;
  for (size_t i = 0; i < sequence.size(); i += 4) {
    const CameraPose& pose = sequence.path()[i].pose;
    const std::vector<int> in_view = scene.boxesInView(pose, k);
    EXPECT_LT(in_view.size(), scene.boxes().size()) << "frame " << i << " culls nothing";
    for (int v = 0; v < k.height; v += 3) {
      for (int u = 0; u < k.width; u += 3) {
        const Eigen::Vector3d ray = pose.rotation() * k.backProject(Eigen::Vector2d(u, v));
        const auto all = scene.castRay(pose.position, ray, 50.0);
        const auto culled = scene.castRay(pose.position, ray, 50.0, in_view);
        ASSERT_TRUE(all && culled);
        ASSERT_EQ(all->box, culled->box);
        ASSERT_EQ(all->t, culled->t);
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Path and rendering

TEST(SyntheticSequence, PathIsSmoothHandheldAndStampedAt30Hz) {
  SyntheticSequenceConfig c = smallConfig(4, 300);
  const SyntheticSequence sequence(c);
  const auto& path = sequence.path();
  ASSERT_EQ(path.size(), 300u);
  EXPECT_EQ(path[0].stamp, 1000.0);
  double length = 0.0;
  for (size_t i = 0; i < path.size(); ++i) {
    const CameraPose& pose = path[i].pose;
    EXPECT_TRUE(sequence.scene().isFree(pose.position, 0.2));
    EXPECT_GE(pose.orientation.w(), 0.0);
    EXPECT_EQ(pose.orientation.normalized().coeffs(), pose.orientation.coeffs());  // stable
    // Looking somewhat down (optical axis below the horizon), never at the ceiling.
    EXPECT_LT(pose.opticalAxis().z(), 0.0);
    // Image "down" (y) points roughly down in the world: a person holds the camera upright.
    EXPECT_LT(pose.rotation().col(1).z(), -0.5);
    if (i == 0) continue;
    const CameraPose& prev = path[i - 1].pose;
    EXPECT_NEAR(path[i].stamp - path[i - 1].stamp, 1.0 / 30.0, 1.1e-6);
    EXPECT_EQ(path[i].stamp, std::round(path[i].stamp * 1e6) / 1e6);  // whole microseconds
    const double step = (pose.position - prev.position).norm();
    EXPECT_LT(step, 0.06);  // at most 1.8 m/s between two frames
    EXPECT_LT(pose.orientation.angularDistance(prev.orientation), 4.0 * kPi / 180.0);
    length += step;
  }
  // About the walking speed on average (sways add a little, never halve or double it).
  const double seconds = path.back().stamp - path.front().stamp;
  EXPECT_GT(length / seconds, 0.8 * c.speed);
  EXPECT_LT(length / seconds, 1.5 * c.speed);
}

TEST(SyntheticSequence, DepthIsTheRayCastZDepthAndOnTheSurface) {
  const SyntheticSequence sequence(smallConfig(9, 10));
  const PinholeIntrinsics& k = sequence.config().intrinsics;
  for (size_t i : {0u, 5u, 9u}) {
    const SyntheticFrame f = sequence.render(i);
    ASSERT_EQ(f.colour.type(), CV_8UC3);
    ASSERT_EQ(f.depth.type(), CV_16UC1);
    ASSERT_EQ(f.depth.cols, 160);
    ASSERT_EQ(f.depth.rows, 120);
    EXPECT_EQ(f.stamp, sequence.path()[i].stamp);
    const CameraPose& pose = f.pose;
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) {
        const Eigen::Vector3d ray_cam = k.backProject(Eigen::Vector2d(u, v));
        const auto hit = sequence.scene().castRay(pose.position, pose.rotation() * ray_cam, 50.0);
        ASSERT_TRUE(hit.has_value());
        ASSERT_EQ(f.depth.at<uint16_t>(v, u), std::lround(hit->t * kUnitsPerMetre))
            << "pixel " << u << "," << v;
        // Back-projected with the quantised depth and the exact pose: on the true surface,
        // within half a depth unit along the ray.
        const double z = depthMetres(f.depth, u, v);
        const Eigen::Vector3d p = pose.position + pose.rotation() * (z * ray_cam);
        ASSERT_LT(sequence.scene().distanceToSurface(p),
                  0.5 / kUnitsPerMetre * ray_cam.norm() + 1e-9);
      }
    }
  }
}

TEST(SyntheticSequence, DepthBeyondMaxRangeIsZero) {
  SyntheticSequenceConfig c = smallConfig(9, 3);
  c.max_range = 1.8;
  const SyntheticSequence sequence(c);
  const SyntheticFrame f = sequence.render(1);
  int zero = 0, valid = 0;
  for (int v = 0; v < f.depth.rows; ++v) {
    for (int u = 0; u < f.depth.cols; ++u) {
      const uint16_t d = f.depth.at<uint16_t>(v, u);
      if (d == 0)
        ++zero;
      else
        ++valid;
      EXPECT_LE(d, std::lround(1.8 * kUnitsPerMetre));
    }
  }
  EXPECT_GT(zero, 0);
  EXPECT_GT(valid, 0);
}

TEST(SyntheticSequence, DepthAgreesBetweenFramesThroughTheExactPoses) {
  const SyntheticSequence sequence(smallConfig(12, 40));
  const PinholeIntrinsics& k = sequence.config().intrinsics;
  for (const auto& [ia, ib] : {std::pair<size_t, size_t>{0, 6}, {10, 13}, {20, 39}}) {
    const SyntheticFrame a = sequence.render(ia), b = sequence.render(ib);
    int projected = 0, agree = 0, see_through = 0;
    for (int v = 0; v < k.height; v += 2) {
      for (int u = 0; u < k.width; u += 2) {
        const double z = depthMetres(a.depth, u, v);
        ASSERT_GT(z, 0.0);
        const Eigen::Vector3d p = a.pose.position + a.pose.rotation() * (z * k.backProject({u, v}));
        const Eigen::Vector3d pb = b.pose.worldToCamera(p);
        if (pb.z() <= 0.0) continue;
        const Eigen::Vector2d px = k.project(pb);
        if (px.x() < 0.0 || px.y() < 0.0 || px.x() > k.width - 1.0 || px.y() > k.height - 1.0)
          continue;
        // Bilinear depth of b where the point lands; skip depth edges (b's 2x2 cell spans one).
        const int u0 = std::min(static_cast<int>(px.x()), k.width - 2);
        const int v0 = std::min(static_cast<int>(px.y()), k.height - 2);
        const double d00 = depthMetres(b.depth, u0, v0), d10 = depthMetres(b.depth, u0 + 1, v0);
        const double d01 = depthMetres(b.depth, u0, v0 + 1),
                     d11 = depthMetres(b.depth, u0 + 1, v0 + 1);
        const double lo = std::min({d00, d10, d01, d11}), hi = std::max({d00, d10, d01, d11});
        if (hi - lo > 0.02) continue;  // a depth edge in b's 2x2 cell
        const double fx = px.x() - u0, fy = px.y() - v0;
        const double db = (1 - fy) * ((1 - fx) * d00 + fx * d10) + fy * ((1 - fx) * d01 + fx * d11);
        ++projected;
        // Two quantisations (0.1 mm each) plus the bilinear error on a slanted plane.
        const double tolerance = 1e-3 + 2e-4 * pb.z();
        if (std::abs(db - pb.z()) < tolerance) {
          ++agree;
        } else if (pb.z() < db - tolerance) {
          ++see_through;  // b would see through a surface a saw: wrong depth or pose
        }                 // else hidden in b behind something nearer: occlusion
      }
    }
    EXPECT_GT(projected, 400) << "frames " << ia << " and " << ib << " overlap too little";
    EXPECT_GT(agree, 0.8 * projected) << "frames " << ia << " and " << ib;
    // Only a point on a silhouette (background in all four neighbours) may look see-through.
    EXPECT_LE(see_through, 0.005 * projected) << "frames " << ia << " and " << ib;
  }
}

TEST(SyntheticSequence, TexturesGiveManyDistinctiveMatchableCorners) {
  SyntheticSequenceConfig c = smallConfig(21, 10);
  c.intrinsics = syntheticIntrinsics(320, 240);
  const SyntheticSequence sequence(c);
  const PinholeIntrinsics& k = c.intrinsics;
  const SyntheticFrame a = sequence.render(0), b = sequence.render(4);
  cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);
  std::vector<cv::KeyPoint> ka, kb;
  cv::Mat da, db;
  orb->detectAndCompute(a.colour, cv::noArray(), ka, da);
  orb->detectAndCompute(b.colour, cv::noArray(), kb, db);
  EXPECT_GT(ka.size(), 350u);
  EXPECT_GT(kb.size(), 350u);
  cv::BFMatcher matcher(cv::NORM_HAMMING);
  std::vector<std::vector<cv::DMatch>> knn;
  matcher.knnMatch(da, db, knn, 2);
  int matches = 0, correct = 0;
  for (const auto& m : knn) {
    if (m.size() < 2 || m[0].distance > 0.8 * m[1].distance) continue;  // Lowe's ratio test
    ++matches;
    const cv::Point2f pa = ka[static_cast<size_t>(m[0].queryIdx)].pt;
    const cv::Point2f pb = kb[static_cast<size_t>(m[0].trainIdx)].pt;
    const int u = std::lround(pa.x), v = std::lround(pa.y);
    if (u < 0 || v < 0 || u >= k.width || v >= k.height) continue;
    const double z = depthMetres(a.depth, u, v);
    const Eigen::Vector3d p =
        a.pose.position + a.pose.rotation() * (z * k.backProject({pa.x, pa.y}));
    const Eigen::Vector2d expected = k.project(b.pose.worldToCamera(p));
    if ((expected - Eigen::Vector2d(pb.x, pb.y)).norm() < 4.0) ++correct;
  }
  // Distinctive texture: many matches survive the ratio test, and nearly all are right.
  EXPECT_GT(matches, 200);
  EXPECT_GT(correct, 0.85 * matches) << correct << " of " << matches;
}

TEST(SyntheticSequence, BadConfigurationsAreRejectedWithTheValue) {
  auto rejects = [](const SyntheticSequenceConfig& c, const std::string& part) {
    try {
      SyntheticSequence s(c);
      ADD_FAILURE() << "accepted, expected an error with '" << part << "'";
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  SyntheticSequenceConfig c = smallConfig();
  c.frames = 0;
  rejects(c, "frames = 0");
  c = smallConfig();
  c.max_range = 20.0;
  rejects(c, "max_range = 20");
  c = smallConfig();
  c.fps = 0.0;
  rejects(c, "fps = 0");
  c = smallConfig();
  c.intrinsics.fx = -1.0;
  rejects(c, "intrinsics");
  c = smallConfig();
  c.scene.room_size = Eigen::Vector3d(2.0, 5.0, 3.0);
  rejects(c, "room size");
  c = smallConfig();
  c.speed = std::nan("");
  rejects(c, "speed");
  EXPECT_THROW(SyntheticSequence(smallConfig(1, 3)).render(3), InvalidArgument);
}

// ---------------------------------------------------------------------------------------------
// The TUM folder

TEST(SyntheticSequence, SameSeedSameBytesOtherSeedOtherImages) {
  TempDir dir;
  const SyntheticSequenceConfig c = smallConfig(7, 6);
  SyntheticSequence(c).writeTumFolder((dir.path() / "a").string());
  SyntheticSequence(c).writeTumFolder((dir.path() / "b").string());
  SyntheticSequence(smallConfig(8, 6)).writeTumFolder((dir.path() / "c").string());
  const auto a = folderContents(dir.path() / "a");
  const auto b = folderContents(dir.path() / "b");
  const auto other = folderContents(dir.path() / "c");
  ASSERT_EQ(a.size(), 6u * 2 + 5);  // 6 colour + 6 depth PNGs, 3 lists, camera.yaml, SOURCE.md
  EXPECT_TRUE(a == b) << "the same seed must give byte-identical files";
  // Whatever the number of threads rendering frames.
  const int threads = cv::getNumThreads();
  cv::setNumThreads(threads == 1 ? 3 : 1);
  SyntheticSequence(c).writeTumFolder((dir.path() / "d").string());
  cv::setNumThreads(threads);
  EXPECT_TRUE(folderContents(dir.path() / "d") == a) << "thread count changed the files";
  ASSERT_EQ(other.size(), a.size());
  int differing_images = 0;
  for (const auto& [name, bytes] : a) {
    ASSERT_TRUE(other.count(name)) << name;  // same stamps, so the same names
    if (name.rfind("rgb/", 0) == 0 || name.rfind("depth/", 0) == 0)
      differing_images += other.at(name) != bytes ? 1 : 0;
  }
  EXPECT_EQ(differing_images, 12);
  EXPECT_NE(a.at("groundtruth.txt"), other.at("groundtruth.txt"));
  EXPECT_EQ(a.at("camera.yaml"), other.at("camera.yaml"));
  EXPECT_NE(a.at("SOURCE.md").find("SYNTHETIC"), std::string::npos);
}

TEST(SyntheticSequence, FolderReadsBackWithExactPosesAndIntrinsics) {
  TempDir dir;
  const SyntheticSequence sequence(smallConfig(3, 25));
  const std::string folder = (dir.path() / "seq").string();
  sequence.writeTumFolder(folder);
  const TumDataset dataset = loadTumDataset(folder);
  EXPECT_EQ(dataset.intrinsics_source, "camera.yaml");
  const PinholeIntrinsics& k = sequence.config().intrinsics;
  EXPECT_EQ(dataset.intrinsics.fx, k.fx);
  EXPECT_EQ(dataset.intrinsics.fy, k.fy);
  EXPECT_EQ(dataset.intrinsics.cx, k.cx);
  EXPECT_EQ(dataset.intrinsics.cy, k.cy);
  EXPECT_EQ(dataset.intrinsics.width, k.width);
  EXPECT_EQ(dataset.intrinsics.height, k.height);
  EXPECT_TRUE(dataset.has_depth);
  EXPECT_EQ(dataset.depth_metres_per_unit, 1.0 / 5000.0);
  EXPECT_EQ(dataset.image_dir, "rgb");
  EXPECT_EQ(dataset.dropped_without_depth, 0u);
  EXPECT_EQ(dataset.dropped_without_pose, 0u);
  ASSERT_EQ(dataset.frames.size(), sequence.size());
  for (size_t i = 0; i < sequence.size(); ++i) {
    const TumFrame& f = dataset.frames[i];
    const TumPoseEntry& truth = sequence.path()[i];
    EXPECT_EQ(f.stamp, truth.stamp);
    EXPECT_EQ(f.depth_stamp, truth.stamp);
    EXPECT_EQ(f.pose_stamp, truth.stamp);
    EXPECT_EQ(f.pose.position, truth.pose.position) << "frame " << i;
    EXPECT_EQ(f.pose.orientation.coeffs(), truth.pose.orientation.coeffs()) << "frame " << i;
  }
  // The images are the rendered ones (PNG is lossless).
  const SyntheticFrame rendered = sequence.render(17);
  const Frame loaded = loadTumFrame(dataset, dataset.frames[17], {true, true});
  EXPECT_EQ(cv::norm(matOf(loaded.image), rendered.colour, cv::NORM_INF), 0.0);
  cv::Mat metres;
  rendered.depth.convertTo(metres, CV_32F, 1.0 / 5000.0);
  EXPECT_LT(cv::norm(matOf(loaded.depth), metres, cv::NORM_INF), 1e-6);
  const cv::Mat raw =
      cv::imread(folder + "/" + dataset.frames[17].depth_path, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(raw.type(), CV_16UC1);
  EXPECT_EQ(cv::norm(raw, rendered.depth, cv::NORM_INF), 0.0);
}

TEST(SyntheticSequence, WritingAgainReplacesTheLists) {
  TempDir dir;
  const std::string folder = (dir.path() / "seq").string();
  SyntheticSequence(smallConfig(3, 8)).writeTumFolder(folder);
  SyntheticSequence(smallConfig(3, 4)).writeTumFolder(folder);
  EXPECT_EQ(loadTumDataset(folder).frames.size(), 4u);
  EXPECT_THROW(SyntheticSequence(smallConfig(3, 2)).writeTumFolder(folder + "/rgb.txt"), IoError);
  // A frame that cannot be written (here a folder stands in its way) fails the whole write with
  // the file named, from whichever thread wrote it, and leaves no rgb.txt behind.
  const std::string blocked = (dir.path() / "blocked").string();
  fs::create_directories(blocked + "/depth/1000.100000.png");
  try {
    SyntheticSequence(smallConfig(3, 8)).writeTumFolder(blocked);
    ADD_FAILURE() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("depth/1000.100000.png"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(blocked + "/rgb.txt"));
}

// ---------------------------------------------------------------------------------------------
// The TUM writers on their own

TEST(TumWriters, TrajectoryRoundTripsExactly) {
  TempDir dir;
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0.0, 3.0);
  std::vector<TumPoseEntry> poses;
  for (int i = 0; i < 200; ++i) {
    TumPoseEntry e;
    e.stamp = 1305031102.175304 + 0.0333 * i + 1e-9 * n(rng);
    // One draw at a time, last first (the order gcc evaluated these arguments in).
    const double z = n(rng), y = n(rng), x = n(rng);
    e.pose.position = Eigen::Vector3d(x, y, 1e-7 * z);
    const double qz = n(rng), qy = n(rng), qx = n(rng), qw = n(rng);
    e.pose.orientation = Eigen::Quaterniond(qw, qx, qy, qz).normalized();
    poses.push_back(e);
  }
  const std::string path = (dir.path() / "groundtruth.txt").string();
  writeTumTrajectory(path, poses, "two\ncomment lines");
  const std::vector<TumPoseEntry> back = readTumTrajectory(path);
  ASSERT_EQ(back.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(back[i].stamp, poses[i].stamp);  // shortest round-trip text: exact
    EXPECT_EQ(back[i].pose.position, poses[i].pose.position);
    // The reader normalises again, which may move the last bit.
    EXPECT_LT((back[i].pose.orientation.coeffs() - poses[i].pose.orientation.coeffs()).norm(),
              1e-15);
  }
  const std::string text = readBytes(path);
  EXPECT_EQ(text.rfind("# two\n# comment lines\n# timestamp tx ty tz qx qy qz qw\n", 0), 0u);

  std::vector<TumPoseEntry> twice = {poses[0], poses[0]};
  EXPECT_THROW(writeTumTrajectory(path, twice), IoError);
  std::vector<TumPoseEntry> bad = {poses[0]};
  bad[0].pose.orientation.coeffs().setZero();
  EXPECT_THROW(writeTumTrajectory(path, bad), IoError);
  bad[0] = poses[0];
  bad[0].pose.position.x() = std::nan("");
  EXPECT_THROW(writeTumTrajectory(path, bad), IoError);
  EXPECT_THROW(writeTumTrajectory((dir.path() / "no/such/folder/gt.txt").string(), poses), IoError);
}

TEST(TumWriters, ImageListRoundTripsAtSixDecimals) {
  TempDir dir;
  const std::vector<TumImageEntry> entries = {{1305031102.175304, "rgb/1305031102.175304.png"},
                                              {1305031102.211214, "rgb/b.png"},
                                              {0.5, "c.png"},
                                              {7.0000004, "deeper/folder/d.png"}};
  const std::string path = (dir.path() / "rgb.txt").string();
  writeTumImageList(path, entries);
  const auto back = readTumImageList(path);
  ASSERT_EQ(back.size(), entries.size());
  for (size_t i = 0; i < entries.size(); ++i) {
    EXPECT_EQ(back[i].path, entries[i].path);
    EXPECT_NEAR(back[i].stamp, entries[i].stamp, 5e-7);
  }
  EXPECT_NE(readBytes(path).find("\n0.500000 c.png\n"), std::string::npos);
  EXPECT_THROW(writeTumImageList(path, {{1.0, "with space.png"}}), IoError);
  EXPECT_THROW(writeTumImageList(path, {{1.0, ""}}), IoError);
  EXPECT_THROW(writeTumImageList(path, {{1.0000001, "a.png"}, {1.0000002, "b.png"}}), IoError);
  EXPECT_THROW(writeTumImageList(path, {{INFINITY, "a.png"}}), IoError);
}

TEST(TumWriters, CameraYamlRoundTripsExactly) {
  TempDir dir;
  PinholeIntrinsics k;
  k.fx = 517.3;
  k.fy = 516.5;
  k.cx = 318.6;
  k.cy = 255.3;
  k.width = 640;
  k.height = 480;
  const std::string path = (dir.path() / "camera.yaml").string();
  writeCameraYaml(path, k);
  const PinholeIntrinsics back = loadCameraYaml(path);
  EXPECT_EQ(back.fx, k.fx);
  EXPECT_EQ(back.fy, k.fy);
  EXPECT_EQ(back.cx, k.cx);
  EXPECT_EQ(back.cy, k.cy);
  EXPECT_EQ(back.width, k.width);
  EXPECT_EQ(back.height, k.height);
  k.cx = 1.0 / 3.0;  // needs all 17 digits
  writeCameraYaml(path, k);
  EXPECT_EQ(loadCameraYaml(path).cx, 1.0 / 3.0);
  k.fx = 0.0;
  EXPECT_THROW(writeCameraYaml(path, k), IoError);
}

// ---------------------------------------------------------------------------------------------
// The method on the generated sequence, and the tool

TEST(SyntheticSequence, ViewSelectionRunsOnIt) {
  TempDir dir;
  const std::string folder = (dir.path() / "seq").string();
  SyntheticSequence(smallConfig(1, 30)).writeTumFolder(folder);
  const TumDataset dataset = loadTumDataset(folder);
  ViewSelectorConfig config;
  config.keyframes.mode = KeyframeMode::kEveryNth;
  config.keyframes.every_n = 3;
  ViewSelector selector(config, makePointSource("depth"));
  for (const TumFrame& f : dataset.frames)
    selector.addFrame(loadTumFrame(dataset, f, {true, false}));
  const ErrorResistanceMatrix& matrix = selector.matrix();
  ASSERT_EQ(matrix.size(), 10u);
  // Neighbouring keyframes (0.07 m apart on a smooth path) see the same walls.
  EXPECT_GE(matrix.table().finiteCount(), 2u * 9);
  for (size_t i = 0; i < matrix.size(); ++i)
    EXPECT_EQ(matrix.keyframe(static_cast<ViewId>(i)).points.cols(), 256);  // depth everywhere
  const Selection s = selector.select();
  EXPECT_GE(s.start_view, 0);
  EXPECT_FALSE(s.pairs.empty());
  EXPECT_FALSE(s.order.empty());
}

/// Runs a command, returns its exit status and stdout + stderr.
std::pair<int, std::string> run(const std::string& command) {
  std::string output;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return {-1, ""};
  char buffer[512];
  while (fgets(buffer, sizeof(buffer), pipe) != nullptr) output += buffer;
  const int status = pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

TEST(GenerateSequenceTool, WritesAFolderAndExplainsMistakes) {
  const std::string tool = std::string(VIEW_SELECTION_TOOLS_DIR) + "/generate_sequence";
  if (!fs::exists(tool)) GTEST_SKIP() << "tool not built: " << tool;
  TempDir dir;
  const std::string out = (dir.path() / "seq").string();
  const std::string small = " --frames 3 --width 64 --height 48 --quiet";

  auto [status, text] = run(tool + " --out " + out + small + " --seed 4");
  ASSERT_EQ(status, 0) << text;
  EXPECT_NE(text.find("wrote 3 frames (64x48"), std::string::npos) << text;
  const TumDataset dataset = loadTumDataset(out);
  EXPECT_EQ(dataset.frames.size(), 3u);
  EXPECT_EQ(dataset.intrinsics.fx, 525.0 * 64 / 640);

  std::tie(status, text) = run(tool + " --out " + out + small);
  EXPECT_EQ(status, 1);
  EXPECT_NE(text.find("not empty"), std::string::npos) << text;
  EXPECT_NE(text.find("--force"), std::string::npos) << text;
  std::tie(status, text) = run(tool + " --out " + out + small + " --force --seed 4 --threads 1");
  EXPECT_EQ(status, 0) << text;

  std::tie(status, text) = run(tool + small);
  EXPECT_EQ(status, 2);
  EXPECT_NE(text.find("--out DIR is required"), std::string::npos) << text;
  std::tie(status, text) = run(tool + " --out " + out + "2 --frames ten");
  EXPECT_EQ(status, 2);
  EXPECT_NE(text.find("--frames expects an integer"), std::string::npos) << text;
  std::tie(status, text) = run(tool + " --out " + out + "2 --width 4");
  EXPECT_EQ(status, 2);
  EXPECT_NE(text.find("--width must be between 8"), std::string::npos) << text;
  std::tie(status, text) = run(tool + " --out " + out + "2 --colour red");
  EXPECT_EQ(status, 2);
  EXPECT_NE(text.find("unknown option '--colour'"), std::string::npos) << text;
  std::tie(status, text) = run(tool + " --out " + out + "/rgb.txt" + small);
  EXPECT_EQ(status, 1);
  EXPECT_NE(text.find("not a folder"), std::string::npos) << text;
  // Exactly one line for a mistake.
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1) << text;
}

}  // namespace
}  // namespace view_selection
