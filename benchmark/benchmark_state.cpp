// State-file benchmarks (Google Benchmark): what a save and a load of the node's session cost.
//   cmake --build BUILD --target benchmarks && BUILD/benchmark_state
// Sessions of 25, 50 and 100 keyframes of the kitchen (../shared/data/redkitchen-0-499, every
// 5th frame, depth points on the default 16 x 16 grid, occlusion maps), or of the built-in
// synthetic sequence without the data. Counters: file bytes and bytes per keyframe.
//   Capture:  the copy the worker takes under its lock (the only part that holds up frames)
//   Encode:   the bytes, on the keeper's thread
//   Write:    encode + atomic write (temporary file, fsync, rename, fsync of the folder)
//   Read:     read + decode + restore into a fresh selector (start-up)
//   AutosaveAtScale/n: one autosave after one new keyframe of a corridor walk of n keyframes
//             (256 points each, no depth maps): what changed captured (the worker's part, a
//             version scan of n rows plus the changed keyframes and rows), encoded as a journal
//             record and appended with fdatasync (the keeper's part). The ...CaptureAtScale
//             variant leaves the disk out (capture + encode only).
#include "view_selection/core/view_selector.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/io/file_ops.h"
#include "view_selection/io/tum_frames.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/session/capture.h"
#include "view_selection/session/delta_tracker.h"
#include "view_selection/session/journal.h"
#include "view_selection/session/state_file.h"
#include "view_selection/sim/synthetic_sequence.h"

#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <random>

namespace view_selection {
namespace {

namespace fs = std::filesystem;

/// A depth session of `keyframes` keyframes, built once per size.
const core::ViewSelector& session(int keyframes) {
  static std::map<int, std::unique_ptr<core::ViewSelector>> built;
  auto& s = built[keyframes];
  if (s) return *s;
  core::ViewSelectorConfig config;
  config.keyframes.mode = core::KeyframeMode::kEveryFrame;
  s = std::make_unique<core::ViewSelector>(config, points::makePointSource("depth"));
  const fs::path kitchen =
      fs::path(VIEW_SELECTION_SOURCE_DIR).parent_path() / "shared" / "data" / "redkitchen-0-499";
  if (fs::exists(kitchen / "rgb.txt")) {
    const io::TumDataset dataset = io::loadTumDataset(kitchen.string());
    for (size_t q = 0; static_cast<int>(s->matrix().size()) < keyframes; q += 5)
      s->addFrame(io::loadTumFrame(dataset, dataset.frames.at(q), {true, false}));
  } else {
    sim::SyntheticSequenceConfig c;
    c.frames = 5 * keyframes;
    const sim::SyntheticSequence sequence(c);
    for (size_t q = 0; static_cast<int>(s->matrix().size()) < keyframes; q += 5) {
      const sim::SyntheticFrame f = sequence.render(q);
      core::Frame frame;
      frame.stamp = f.stamp;
      frame.image_name = std::to_string(q) + ".png";
      frame.intrinsics = c.intrinsics;
      frame.pose = f.pose;
      frame.depth = images::depthImageOf(images::depthToMetres(f.depth, 1.0 / 5000.0));
      s->addFrame(frame);
    }
  }
  return *s;
}

void counters(benchmark::State& state, size_t bytes) {
  const double n = static_cast<double>(state.range(0));
  state.counters["file_bytes"] = static_cast<double>(bytes);
  state.counters["bytes_per_keyframe"] = static_cast<double>(bytes) / n;
}

void BM_Capture(benchmark::State& state) {
  const core::ViewSelector& s = session(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(session::captureSession(s));
  counters(state, session::encodeState(session::captureSession(s)).size());
}

void BM_Encode(benchmark::State& state) {
  const session::SessionState captured = session::captureSession(session(static_cast<int>(state.range(0))));
  size_t bytes = 0;
  for (auto _ : state) bytes = session::encodeState(captured).size();
  counters(state, bytes);
}

std::string scratch() {
  const fs::path dir = fs::temp_directory_path() / ("benchmark_state_" + std::to_string(getpid()));
  fs::create_directories(dir);
  return (dir / "session.state").string();
}

void BM_Write(benchmark::State& state) {
  const session::SessionState captured = session::captureSession(session(static_cast<int>(state.range(0))));
  const std::string path = scratch();
  size_t bytes = 0;
  for (auto _ : state) bytes = session::writeStateFile(path, captured);
  counters(state, bytes);
  fs::remove_all(fs::path(path).parent_path());
}

void BM_Read(benchmark::State& state) {
  const session::SessionState captured = session::captureSession(session(static_cast<int>(state.range(0))));
  const std::string path = scratch();
  const size_t bytes = session::writeStateFile(path, captured);
  for (auto _ : state) {
    auto selector = session::selectorFor(session::readStateFile(path));
    benchmark::DoNotOptimize(selector);
  }
  counters(state, bytes);
  fs::remove_all(fs::path(path).parent_path());
}

// ---------------------------------------------------------------------------------------------
// Autosave at scale: a corridor walk (0.2 m between keyframes, 256 points a keyframe ray-cast
// onto walls 2 m and 1.5 m away, 25 m at most), as benchmark_core's, fed through a ViewSelector
// whose points are given.

class GivenPoints : public core::PointSource {
 public:
  std::string name() const override { return "given"; }
  core::PointSourceResult process(core::ViewId, const core::Frame&) override {
    core::PointSourceResult r;
    r.points = std::move(next_);
    return r;
  }
  void reset() override {}
  Eigen::Matrix3Xd next_;
};

struct Walk {
  std::unique_ptr<core::ViewSelector> selector;
  GivenPoints* points = nullptr;
  std::mt19937 rng{42};
  int next = 0;

  void add() {
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    const int index = next++;
    core::Frame f;
    f.stamp = 1.0 + index;
    f.image_name = std::to_string(index) + ".png";
    f.intrinsics.fx = f.intrinsics.fy = 525.0;
    f.intrinsics.cx = 319.5;
    f.intrinsics.cy = 239.5;
    f.intrinsics.width = 640;
    f.intrinsics.height = 480;
    const Eigen::Vector3d eye(0.8 * std::sin(0.05 * index), 0.1 * std::sin(0.13 * index),
                              0.2 * index);
    const double yaw = 0.7 * std::sin(0.031 * index);
    const Eigen::Vector3d z = Eigen::Vector3d(std::sin(yaw), 0.05, std::cos(yaw)).normalized();
    const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
    Eigen::Matrix3d r;
    r << x, z.cross(x), z;
    f.pose.position = eye;
    f.pose.orientation = Eigen::Quaterniond(r);
    Eigen::Matrix3Xd p(3, 256);
    for (int q = 0; q < 256; ++q) {
      const double u = uni(rng) * 640, v = uni(rng) * 480;
      const Eigen::Vector3d ray = r * Eigen::Vector3d((u - 319.5) / 525.0, (v - 239.5) / 525.0, 1.0);
      double t = 25.0;
      for (int axis = 0; axis < 2; ++axis) {
        const double half = axis == 0 ? 2.0 : 1.5;
        if (std::abs(ray[axis]) > 1e-9)
          t = std::min(t, ((ray[axis] > 0 ? half : -half) - eye[axis]) / ray[axis]);
      }
      p.col(q) = eye + t * ray;
    }
    points->next_ = std::move(p);
    selector->addFrame(f);
  }
};

Walk& walk(int n) {
  static std::map<int, Walk> built;
  Walk& w = built[n];
  if (w.selector) return w;
  core::ViewSelectorConfig config;
  config.keyframes.mode = core::KeyframeMode::kEveryFrame;
  auto points = std::make_unique<GivenPoints>();
  w.points = points.get();
  w.selector = std::make_unique<core::ViewSelector>(config, std::move(points));
  while (static_cast<int>(w.selector->matrix().size()) < n) w.add();
  return w;
}

void autosave(benchmark::State& state, bool disk) {
  Walk& w = walk(static_cast<int>(state.range(0)));
  session::DeltaTracker tracker;
  tracker.markSaved(*w.selector);
  const std::string path = session::journalPath(scratch());
  size_t bytes = 0, keyframes = 0, rows = 0;
  for (auto _ : state) {
    state.PauseTiming();
    w.add();
    state.ResumeTiming();
    const session::SessionDelta delta = tracker.capture(*w.selector);
    const std::vector<uint8_t> record = session::encodeJournalRecord(1, 0, delta);
    if (disk) io::appendToFile(path, record);
    bytes = record.size();
    keyframes = delta.keyframes.size();
    rows = delta.rows.size();
  }
  state.counters["record_bytes"] = static_cast<double>(bytes);
  state.counters["keyframes_in_record"] = static_cast<double>(keyframes);
  state.counters["rows_in_record"] = static_cast<double>(rows);
  fs::remove_all(fs::path(path).parent_path());
}

void BM_AutosaveAtScale(benchmark::State& state) { autosave(state, true); }
void BM_AutosaveCaptureAtScale(benchmark::State& state) { autosave(state, false); }

BENCHMARK(BM_AutosaveAtScale)->Arg(10000)->Arg(100000)->Iterations(50)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AutosaveCaptureAtScale)->Arg(10000)->Arg(100000)->Iterations(50)->Unit(benchmark::kMillisecond);

BENCHMARK(BM_Capture)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Encode)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Write)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Read)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace view_selection

BENCHMARK_MAIN();
