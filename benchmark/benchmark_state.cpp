// State-file benchmarks (Google Benchmark): what a save and a load of the node's session cost.
//   cmake --build BUILD --target benchmarks && BUILD/benchmark_state
// Sessions of 25, 50 and 100 keyframes of the kitchen (../shared/data/redkitchen-0-499, every
// 5th frame, depth points on the default 16 x 16 grid, occlusion maps), or of the built-in
// synthetic sequence without the data. Counters: file bytes and bytes per keyframe.
//   Capture:  the copy the worker takes under its lock (the only part that holds up frames)
//   Encode:   the bytes, on the keeper's thread
//   Write:    encode + atomic write (temporary file, fsync, rename, fsync of the folder)
//   Read:     read + decode + restore into a fresh selector (start-up)
#include "view_selection/core/view_selector.h"
#include "view_selection/io/state_file.h"
#include "view_selection/io/tum_frames.h"
#include "view_selection/points/image_conversion.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/sim/synthetic_sequence.h"

#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <map>
#include <memory>

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
      frame.depth = points::depthImageOf(points::depthToMetres(f.depth, 1.0 / 5000.0));
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
  for (auto _ : state) benchmark::DoNotOptimize(io::captureSession(s));
  counters(state, io::encodeState(io::captureSession(s)).size());
}

void BM_Encode(benchmark::State& state) {
  const io::SessionState captured = io::captureSession(session(static_cast<int>(state.range(0))));
  size_t bytes = 0;
  for (auto _ : state) bytes = io::encodeState(captured).size();
  counters(state, bytes);
}

std::string scratch() {
  const fs::path dir = fs::temp_directory_path() / ("benchmark_state_" + std::to_string(getpid()));
  fs::create_directories(dir);
  return (dir / "session.state").string();
}

void BM_Write(benchmark::State& state) {
  const io::SessionState captured = io::captureSession(session(static_cast<int>(state.range(0))));
  const std::string path = scratch();
  size_t bytes = 0;
  for (auto _ : state) bytes = io::writeStateFile(path, captured);
  counters(state, bytes);
  fs::remove_all(fs::path(path).parent_path());
}

void BM_Read(benchmark::State& state) {
  const io::SessionState captured = io::captureSession(session(static_cast<int>(state.range(0))));
  const std::string path = scratch();
  const size_t bytes = io::writeStateFile(path, captured);
  for (auto _ : state) {
    auto selector = io::selectorFor(io::readStateFile(path));
    benchmark::DoNotOptimize(selector);
  }
  counters(state, bytes);
  fs::remove_all(fs::path(path).parent_path());
}

BENCHMARK(BM_Capture)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Encode)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Write)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Read)->Arg(25)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace view_selection

BENCHMARK_MAIN();
