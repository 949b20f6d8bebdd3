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
#include "view_selection/core/selection_cache.h"
#include "view_selection/core/selection_output.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/eval/reference_error_resistance.h"

#include <benchmark/benchmark.h>
#include <unistd.h>

#include <algorithm>
#include <deque>
#include <fstream>
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

void BM_ErrorResistanceBatched(benchmark::State& state) {
  // The form the matrix uses: one pair's points as arrays, vectorised.
  const PointSet s = pointSet();
  const PairErrorResistance pair(s.pose_i.position, s.k, s.pose_j);
  std::vector<double> x, y, z, out(s.world.size());
  for (const auto& p : s.world) {
    const Eigen::Vector3d c = s.pose_j.worldToCamera(p);
    x.push_back(c.x());
    y.push_back(c.y());
    z.push_back(c.z());
  }
  for (auto _ : state) {
    pair.evaluate(x.data(), y.data(), z.data(), x.size(), out.data());
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(x.size()));
}
BENCHMARK(BM_ErrorResistanceBatched);

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

// --- loop-closure corrections ------------------------------------------------------------------

// A correction of `fraction` of the keyframes, as a loop closure gives: the most recent ones
// (contiguous: 1) or scattered at random (0), each moved by a drift growing to 5 cm and 0.5 deg.
std::vector<std::pair<ViewId, CameraPose>> correction(const ErrorResistanceMatrix& m,
                                                      double fraction, bool contiguous) {
  const int n = static_cast<int>(m.size());
  const int moved = static_cast<int>(fraction * n + 0.5);
  std::vector<ViewId> ids;
  if (contiguous) {
    for (int q = n - moved; q < n; ++q) ids.push_back(q);
  } else {
    std::mt19937 rng(3);
    std::vector<ViewId> all(static_cast<size_t>(n));
    for (int q = 0; q < n; ++q) all[static_cast<size_t>(q)] = q;
    std::shuffle(all.begin(), all.end(), rng);
    ids.assign(all.begin(), all.begin() + moved);
    std::sort(ids.begin(), ids.end());
  }
  std::vector<std::pair<ViewId, CameraPose>> out;
  for (size_t q = 0; q < ids.size(); ++q) {
    const double s = (q + 1.0) / static_cast<double>(ids.size());
    CameraPose p = m.keyframe(ids[q]).pose;
    p.position += Eigen::Vector3d(0.05 * s, 0.0, -0.03 * s);
    p.orientation =
        (Eigen::AngleAxisd(0.5 * s * M_PI / 180.0, Eigen::Vector3d::UnitY()) * p.orientation)
            .normalized();
    out.emplace_back(ids[q], p);
  }
  return out;
}

// Arguments: n, percent of the keyframes moved (100: recomputing everything), contiguous,
// gate (0: paper, 1: matchable). docs/node.md compares 10% against 100%.
void BM_CorrectPosesCorridor(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const Gate gate = state.range(3) ? Gate::kMatchable : Gate::kPaper;
  const ErrorResistanceMatrix& base = cachedMatrix(corridorKeyframe, n, gate);
  const auto moves = correction(base, state.range(1) / 100.0, state.range(2) != 0);
  std::unique_ptr<ErrorResistanceMatrix> copy;
  size_t evaluated = 0;
  for (auto _ : state) {
    state.PauseTiming();
    copy = std::make_unique<ErrorResistanceMatrix>(base);
    const size_t before = copy->pairsEvaluated();
    state.ResumeTiming();
    copy->setPoses(moves);
    state.PauseTiming();
    evaluated = copy->pairsEvaluated() - before;
    state.ResumeTiming();
  }
  state.counters["moved"] = static_cast<double>(moves.size());
  state.counters["pairs_projected"] = static_cast<double>(evaluated);
}
BENCHMARK(BM_CorrectPosesCorridor)
    ->ArgsProduct({{2000}, {10, 100}, {1, 0}, {1, 0}})
    ->ArgNames({"n", "percent", "contiguous", "matchable"})
    ->Unit(benchmark::kMillisecond);

// --- at scale: 10k to 100k keyframes ----------------------------------------------------------

/// Resident memory of this process [bytes] (/proc/self/statm).
double residentBytes() {
  std::ifstream statm("/proc/self/statm");
  double pages = 0.0, resident = 0.0;
  statm >> pages >> resident;
  return resident * static_cast<double>(sysconf(_SC_PAGESIZE));
}

/// The matrix grown to n keyframes once per n (the default, matchable gate), with the resident
/// memory it added.
struct Grown {
  std::unique_ptr<ErrorResistanceMatrix> matrix;
  std::mt19937 rng{42};
  double bytes = 0.0;
};
Grown& grownCorridor(int n) {
  static std::map<int, Grown> cache;
  Grown& g = cache[n];
  if (!g.matrix) {
    const double before = residentBytes();
    g.matrix = std::make_unique<ErrorResistanceMatrix>();
    for (int q = 0; q < n; ++q) g.matrix->addKeyframe(corridorKeyframe(q, g.rng));
    g.bytes = residentBytes() - before;
  }
  return g;
}

// Each iteration inserts the next keyframe of the walk into the grown matrix (n grows by the
// iterations, a fraction of a percent). Counters: memory a keyframe (points, occlusion map,
// matrix entries, per-view data), finite entries a row, pairs projected per insertion.
void BM_InsertKeyframeCorridorAtScale(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  Grown& g = grownCorridor(n);
  ErrorResistanceMatrix& m = *g.matrix;
  const size_t keyframes_before = m.size();
  const size_t evaluated_before = m.pairsEvaluated();
  for (auto _ : state) {
    state.PauseTiming();
    Keyframe next = corridorKeyframe(static_cast<int>(m.size()), g.rng);
    state.ResumeTiming();
    m.addKeyframe(std::move(next));
  }
  const double inserted = static_cast<double>(m.size() - keyframes_before);
  state.counters["bytes_per_keyframe"] = g.bytes / n;
  state.counters["finite_per_row"] = static_cast<double>(m.table().finiteCount()) / static_cast<double>(m.size());
  state.counters["pairs_projected"] = static_cast<double>(m.pairsEvaluated() - evaluated_before) / inserted;
}
BENCHMARK(BM_InsertKeyframeCorridorAtScale)
    ->Arg(10000)
    ->Arg(50000)
    ->Arg(100000)
    ->Iterations(200)
    ->Unit(benchmark::kMillisecond);

/// A point source that gives nothing: the scale_free decision benchmark never inserts.
class NoPoints : public PointSource {
 public:
  std::string name() const override { return "none"; }
  PointSourceResult process(ViewId, const Frame&) override { return {}; }
  void reset() override {}
};

// The scale_free decision (ViewSelector::wantsFrame, the whole policy step of addFrame: a frame
// it skips costs nothing else) with state.range(0) keyframes in the selector, for frames 0.02 m
// apart along the corridor from the pose of keyframe `at` (its index, given the keyframe count).
template <typename At>
void scaleFreeDecisions(benchmark::State& state, At at) {
  const int n = static_cast<int>(state.range(0));
  Grown& g = grownCorridor(n);
  ViewSelectorState saved;  // the grown matrix in a selector (its finite entries as they are)
  saved.config.keyframes.mode = KeyframeMode::kScaleFree;
  const ErrorResistanceMatrix& m = *g.matrix;
  for (size_t i = 0; i < m.size(); ++i) {
    saved.keyframes.push_back(m.keyframe(static_cast<ViewId>(i)));
    saved.rows.push_back(m.table().row(static_cast<ViewId>(i)));
  }
  ViewSelector selector(saved.config, std::make_unique<NoPoints>());
  selector.restore(saved);
  saved = {};
  const Keyframe& from = m.keyframe(static_cast<ViewId>(at(m.size())));
  Frame frame;
  frame.intrinsics = from.intrinsics;
  size_t wanted = 0, offered = 0;
  for (auto _ : state) {
    frame.pose = from.pose;
    frame.pose.position.z() += 0.02 * static_cast<double>(offered % 10);
    wanted += selector.wantsFrame(frame) ? 1 : 0;
    ++offered;
  }
  state.counters["keyframes"] = static_cast<double>(selector.matrix().size());
  state.counters["wanted_share"] = static_cast<double>(wanted) / static_cast<double>(offered);
}

// The default keyframe policy's decision (scale_free: the next frame against the last
// keyframe's 256 points), frames past the last keyframe. It compares with the last keyframe
// only, so the time must not grow with n.
void BM_ScaleFreeDecisionAtScale(benchmark::State& state) {
  scaleFreeDecisions(state, [](size_t keyframes) { return keyframes - 1; });
}
BENCHMARK(BM_ScaleFreeDecisionAtScale)->Arg(10000)->Arg(100000)->Unit(benchmark::kMicrosecond);

// The same decision for a frame back at an earlier place of the corridor (at keyframe n/2, give
// or take a few cm): new against the last keyframe, so the revisit rule searches the keyframes
// near it (KeyframeNeighbours) and measures the most alike until one has the view.
void BM_ScaleFreeRevisitDecisionAtScale(benchmark::State& state) {
  scaleFreeDecisions(state, [](size_t keyframes) { return keyframes / 2; });
}
BENCHMARK(BM_ScaleFreeRevisitDecisionAtScale)->Arg(10000)->Arg(100000)->Unit(benchmark::kMicrosecond);

// Selection after each insertion, at scale: the incremental cache that ViewSelector keeps (each
// iteration inserts one keyframe untimed, then updates the selection), and the plain
// definition over the same matrix for comparison.
void BM_SelectAfterInsertionAtScale(benchmark::State& state) {
  Grown& g = grownCorridor(static_cast<int>(state.range(0)));
  ErrorResistanceMatrix& m = *g.matrix;
  const SelectionConfig config;
  SelectionCache cache;
  cache.update(m.table(), config);
  for (auto _ : state) {
    state.PauseTiming();
    m.addKeyframe(corridorKeyframe(static_cast<int>(m.size()), g.rng));
    state.ResumeTiming();
    benchmark::DoNotOptimize(cache.update(m.table(), config).pairs.size());
  }
  state.counters["pairs"] = static_cast<double>(cache.selection().pairs.size());
  const ChunkedSelection& last = cache.selection();
  state.counters["completed"] = static_cast<double>(last.completed.size());
  // How much of the order the plain traversal reached before completion took over.
  const auto first = last.completed.empty()
                         ? last.order.end()
                         : std::find(last.order.begin(), last.order.end(), last.completed.front().view);
  state.counters["traversed"] = static_cast<double>(first - last.order.begin());
}
BENCHMARK(BM_SelectAfterInsertionAtScale)
    ->Arg(10000)
    ->Arg(50000)
    ->Arg(100000)
    ->Iterations(50)
    ->Unit(benchmark::kMillisecond);

// What the node does after each insertion besides the selection's update: an output of the
// keyframes, E and the selection for its readers (ViewSelector::output()), and the release of
// an output readers held before (both timed). Every list is chunked and shared copy-on-write,
// so this costs a pointer a chunk, not a copy a view.
void BM_SnapshotAtScale(benchmark::State& state) {
  Grown& g = grownCorridor(static_cast<int>(state.range(0)));
  ErrorResistanceMatrix& m = *g.matrix;
  SelectionCache cache;
  const SelectionConfig config;
  cache.update(m.table(), config);
  std::deque<SelectionOutput> held;  // readers still hold the previous ones
  for (auto _ : state) {
    state.PauseTiming();
    m.addKeyframe(corridorKeyframe(static_cast<int>(m.size()), g.rng));
    const ChunkedSelection& selection = cache.update(m.table(), config);
    state.ResumeTiming();
    SelectionOutput out;
    out.keyframes = m.summaries();
    out.names = m.imageNames();
    out.table = m.table();
    out.selection = selection;
    out.config = config;
    held.push_back(std::move(out));
    if (held.size() > 2) held.pop_front();  // the oldest released: timed too
  }
}
BENCHMARK(BM_SnapshotAtScale)->Arg(10000)->Arg(100000)->Iterations(30)->Unit(benchmark::kMillisecond);

// For comparison, what a copy of E cost before its lists were shared: every row, column and
// best-entries list copied.
void BM_DeepCopyOfTheTableAtScale(benchmark::State& state) {
  Grown& g = grownCorridor(static_cast<int>(state.range(0)));
  const ErrorResistanceTable& e = g.matrix->table();
  for (auto _ : state) {
    std::vector<std::vector<TableEntry>> rows, cols, tops;
    rows.reserve(e.size());
    cols.reserve(e.size());
    tops.reserve(e.size());
    for (size_t i = 0; i < e.size(); ++i) {
      rows.push_back(e.row(static_cast<ViewId>(i)));
      cols.push_back(e.column(static_cast<ViewId>(i)));
      tops.push_back(e.top(static_cast<ViewId>(i)));
    }
    benchmark::DoNotOptimize(rows.data());
  }
}
BENCHMARK(BM_DeepCopyOfTheTableAtScale)->Arg(10000)->Arg(100000)->Iterations(10)->Unit(benchmark::kMillisecond);

void BM_SelectFullAtScale(benchmark::State& state) {
  Grown& g = grownCorridor(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(selectViews(g.matrix->table(), {}).pairs.data());
}
BENCHMARK(BM_SelectFullAtScale)->Arg(10000)->Arg(100000)->Iterations(5)->Unit(benchmark::kMillisecond);

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
