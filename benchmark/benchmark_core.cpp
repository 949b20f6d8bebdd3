// Core benchmarks (Google Benchmark). Build and run:
//   cmake --build build --target benchmarks
//   ./build/benchmark_core --benchmark_min_time=0.5
// Scenes are synthetic and seeded:
//   corridor: a SLAM-like walk down a long corridor (0.2 m between keyframes, walls 2 m away),
//             each view overlapping a few dozen neighbours: the online node's usual situation.
//   object:   every camera on a sphere looking at one object (a DTU-like scan): every pair is
//             co-visible, the worst case for the matrix.
#include "view_selection/core/error_resistance.h"
#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/selection.h"
#include "view_selection/eval/reference_error_resistance.h"

#include <benchmark/benchmark.h>

#include <map>
#include <memory>
#include <random>
#include <tuple>

namespace view_selection::core {
namespace {

PinholeIntrinsics vga() {
  PinholeIntrinsics k;
  k.fx = k.fy = 525.0;
  k.cx = 319.5;
  k.cy = 239.5;
  k.width = 640;
  k.height = 480;
  return k;
}

CameraPose lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d helper =
      std::abs(z.y()) < 0.9 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d x = helper.cross(z).normalized();
  Eigen::Matrix3d r;
  r << x, z.cross(x), z;
  CameraPose p;
  p.position = eye;
  p.orientation = Eigen::Quaterniond(r);
  return p;
}

/// Corridor x in [-2, 2], y in [-1.5, 1.5] (y down), along +z. Points: 256 random pixels of the
/// view ray-cast onto the walls; a coarse z-buffer depth map like a real RGB-D keyframe's.
Keyframe corridorKeyframe(int index, std::mt19937& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double z = 0.2 * index;
  const Eigen::Vector3d eye(0.8 * std::sin(0.05 * index), 0.1 * std::sin(0.13 * index), z);
  const double yaw = 0.7 * std::sin(0.031 * index);  // looking ahead, swinging to the walls
  const Eigen::Vector3d target = eye + Eigen::Vector3d(std::sin(yaw), 0.05, std::cos(yaw));
  Keyframe kf;
  kf.stamp = index;
  kf.intrinsics = vga();
  kf.pose = lookAt(eye, target);
  const Eigen::Matrix3d r = kf.pose.rotation();
  auto cast = [&](double u, double v) {
    const Eigen::Vector3d ray = r * kf.intrinsics.backProject({u, v});
    double t = 1e9;
    for (int axis = 0; axis < 2; ++axis) {
      const double half = axis == 0 ? 2.0 : 1.5;
      if (std::abs(ray[axis]) > 1e-9)
        t = std::min(t, ((ray[axis] > 0 ? half : -half) - eye[axis]) / ray[axis]);
    }
    return std::min(t, 25.0);  // the corridor's far end is a wall 25 m ahead
  };
  kf.points.resize(3, 256);
  for (int q = 0; q < 256; ++q) {
    const double u = uni(rng) * 640, v = uni(rng) * 480;
    kf.points.col(q) = eye + cast(u, v) * (r * kf.intrinsics.backProject({u, v}));
  }
  auto map = std::make_shared<DepthMap>();
  map->cols = 80;
  map->rows = 60;
  map->cell_width = map->cell_height = 8.0;
  map->depth.resize(80 * 60);
  for (int row = 0; row < 60; ++row)
    for (int col = 0; col < 80; ++col)
      map->depth[static_cast<size_t>(row * 80 + col)] =
          static_cast<float>(cast(col * 8 + 4, row * 8 + 4));
  kf.depth = map;
  return kf;
}

/// Cameras on a sphere of radius 3 around a 1 m object; 256 points on the object's front.
Keyframe objectKeyframe(int index, std::mt19937& rng) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double az = 2.4 * index, el = 0.3 + 0.5 * uni(rng);
  const Eigen::Vector3d eye = 3.0 * Eigen::Vector3d(std::cos(el) * std::cos(az), -std::sin(el),
                                                    std::cos(el) * std::sin(az));
  Keyframe kf;
  kf.stamp = index;
  kf.intrinsics = vga();
  kf.pose = lookAt(eye, Eigen::Vector3d::Zero());
  kf.points.resize(3, 256);
  for (int q = 0; q < 256; ++q) {
    // One draw at a time, z first (gcc's order for these as arguments, which is unspecified).
    const double z = uni(rng), y = uni(rng), x = uni(rng);
    Eigen::Vector3d p(x - 0.5, y - 0.5, z - 0.5);
    kf.points.col(q) = p;
  }
  return kf;
}

using Maker = Keyframe (*)(int, std::mt19937&);

ErrorResistanceConfig gateConfig(Gate gate) {
  ErrorResistanceConfig config;
  config.gate = gate;
  return config;
}

const ErrorResistanceMatrix& cachedMatrix(Maker make, int n, Gate gate = Gate::kPaper) {
  static std::map<std::tuple<Maker, int, Gate>, std::unique_ptr<ErrorResistanceMatrix>> cache;
  auto& slot = cache[{make, n, gate}];
  if (!slot) {
    slot = std::make_unique<ErrorResistanceMatrix>(gateConfig(gate));
    std::mt19937 rng(42);
    for (int q = 0; q < n; ++q) slot->addKeyframe(make(q, rng));
  }
  return *slot;
}

// --- r(P; i -> j) -------------------------------------------------------------------------------

struct PointSet {
  std::vector<Eigen::Vector3d> world;
  CameraPose pose_i, pose_j;
  PinholeIntrinsics k = vga();
};

PointSet pointSet() {
  PointSet s;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> uni(-0.5, 0.5);
  s.pose_i = lookAt({0, 0, 0}, {0, 0, 3});
  s.pose_j = lookAt({1.2, 0.1, 0.3}, {0, 0, 3});
  for (int q = 0; q < 1024; ++q) {
    const double z = uni(rng), y = uni(rng), x = uni(rng);  // z first, as above
    s.world.emplace_back(x, y, 3.0 + z);
  }
  return s;
}

void BM_ErrorResistanceClosedForm(benchmark::State& state) {
  const PointSet s = pointSet();
  const PairErrorResistance pair(s.pose_i.position, s.k, s.pose_j);
  std::vector<Eigen::Vector3d> cam;
  for (const auto& p : s.world) cam.push_back(s.pose_j.worldToCamera(p));
  for (auto _ : state)
    for (const auto& p : cam) benchmark::DoNotOptimize(pair(p));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(cam.size()));
}
BENCHMARK(BM_ErrorResistanceClosedForm);

void BM_ErrorResistanceClosedFormPerCall(benchmark::State& state) {
  // Including the per-pair set-up and the world-to-camera transform on every call.
  const PointSet s = pointSet();
  for (auto _ : state)
    for (const auto& p : s.world)
      benchmark::DoNotOptimize(pointErrorResistance(p, s.pose_i.position, s.k, s.pose_j));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(s.world.size()));
}
BENCHMARK(BM_ErrorResistanceClosedFormPerCall);

void BM_ErrorResistanceBruteForce(benchmark::State& state) {
  const PointSet s = pointSet();
  for (auto _ : state)
    for (const auto& p : s.world)
      benchmark::DoNotOptimize(
          eval::pointErrorResistanceByTriangulation(p, s.k, s.pose_i, s.k, s.pose_j));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(s.world.size()));
}
BENCHMARK(BM_ErrorResistanceBruteForce);

// --- keyframe insertion -------------------------------------------------------------------------

// Arguments: n, then the gate (0: paper, 1: matchable with its defaults).
void insertion(benchmark::State& state, Maker make) {
  const int n = static_cast<int>(state.range(0));
  const Gate gate = state.range(1) ? Gate::kMatchable : Gate::kPaper;
  const ErrorResistanceMatrix& base = cachedMatrix(make, n, gate);
  std::mt19937 rng(7);
  const Keyframe next = make(n, rng);
  size_t evaluated = 0;
  std::unique_ptr<ErrorResistanceMatrix> copy;
  for (auto _ : state) {
    state.PauseTiming();  // copying (and destroying the last copy) is not part of an insertion
    copy = std::make_unique<ErrorResistanceMatrix>(base);
    const size_t before = copy->pairsEvaluated();
    state.ResumeTiming();
    copy->addKeyframe(next);
    state.PauseTiming();
    evaluated = copy->pairsEvaluated() - before;
    state.ResumeTiming();
  }
  state.counters["pairs_projected"] = static_cast<double>(evaluated);
  state.counters["finite_per_row"] = static_cast<double>(base.table().finiteCount()) / n;
}

void BM_InsertKeyframeCorridor(benchmark::State& state) { insertion(state, corridorKeyframe); }
BENCHMARK(BM_InsertKeyframeCorridor)
    ->ArgsProduct({{100, 1000, 2000}, {0, 1}})
    ->ArgNames({"n", "matchable"})
    ->Unit(benchmark::kMillisecond);

void BM_InsertKeyframeObject(benchmark::State& state) { insertion(state, objectKeyframe); }
BENCHMARK(BM_InsertKeyframeObject)
    ->ArgsProduct({{100, 1000, 2000}, {0, 1}})
    ->ArgNames({"n", "matchable"})
    ->Unit(benchmark::kMillisecond);

// --- selection ----------------------------------------------------------------------------------

void selection(benchmark::State& state, Maker make, CompletionMode mode) {
  const ErrorResistanceMatrix& m = cachedMatrix(make, static_cast<int>(state.range(0)));
  size_t pairs = 0;
  for (auto _ : state) {
    const Selection s = selectViews(m.table(), {5, mode});
    pairs = s.pairs.size();
    benchmark::DoNotOptimize(s);
  }
  state.counters["pairs"] = static_cast<double>(pairs);
  state.counters["finite_entries"] = static_cast<double>(m.table().finiteCount());
}

void BM_SelectCorridorPaper(benchmark::State& state) {
  selection(state, corridorKeyframe, CompletionMode::kPaper);
}
BENCHMARK(BM_SelectCorridorPaper)->Arg(1000)->Arg(2000)->Arg(5000)->Unit(benchmark::kMillisecond);
void BM_SelectCorridorReachable(benchmark::State& state) {
  selection(state, corridorKeyframe, CompletionMode::kReachable);
}
BENCHMARK(BM_SelectCorridorReachable)
    ->Arg(1000)
    ->Arg(2000)
    ->Arg(5000)
    ->Unit(benchmark::kMillisecond);
void BM_SelectObjectReachable(benchmark::State& state) {
  selection(state, objectKeyframe, CompletionMode::kReachable);
}
BENCHMARK(BM_SelectObjectReachable)->Arg(1000)->Arg(2000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace view_selection::core

BENCHMARK_MAIN();
