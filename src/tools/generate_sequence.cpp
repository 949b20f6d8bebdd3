// generate_sequence: writes the built-in synthetic RGB-D sequence (a textured room seen by a
// handheld-like camera, exact poses) as a TUM-layout folder. Deterministic from --seed.
#include "command_line.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/sim/corridor_walk.h"
#include "view_selection/sim/synthetic_sequence.h"

#include <opencv2/core/utility.hpp>

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>

namespace fs = std::filesystem;
using namespace view_selection::core;
using namespace view_selection::io;
using namespace view_selection::sim;
using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;

namespace {

const char* kUsage = R"(usage: generate_sequence --out DIR [options]

Renders the built-in synthetic sequence: a textured 6 x 5 x 3 m room with boxes, seen by a
handheld-like camera walking a loop. Writes a TUM RGB-D folder (rgb/, depth/, rgb.txt,
depth.txt, groundtruth.txt with exact poses, camera.yaml, SOURCE.md) that select_views reads.
The same seed and options give byte-identical files.

  --out DIR        output folder (created; must be empty unless --force)
  --frames N       number of frames (default 300)
  --seed S         seed of textures, layout, path and noise (default 1)
  --width W        image width (default 640)
  --height H       image height (default 480)
  --fx F --fy F    focal lengths [px] (default 525 at 640 wide, scaled with --width)
  --cx C --cy C    principal point [px] (default the image centre, (W-1)/2 and (H-1)/2)
  --fps R          frame rate [Hz] (default 30)
  --speed V        walking speed [m/s] (default 0.7: about one loop in 300 frames)
  --noise SIGMA    colour noise [grey levels] (default 2; 0 for none)
  --threads N      frames rendered at once (default 0: one per core; the files are the same)
  --ring-step DEG  a photo collection instead of the walk: --frames views on a ring (or an arc,
                   when --frames x DEG < 360) around the box on the table, DEG apart in azimuth
  --ring-distance M  from the box's centre [m] (default 0.8)
  --ring-elevation DEG  above it (default 30)
  --no-depth       no depth images (a photo collection, as DTU)
  --unit-scale S   write the poses in metres x S (1000: millimetres); needs --no-depth
  --points-only    no rendering: a walk down a long corridor (a building-sized SLAM session),
                   one keyframe every 0.2 m with 256 points ray-cast onto its walls, written as
                   points.bin (poses and points), groundtruth.txt, camera.yaml; select_views
                   reads it. For runs at 100k keyframes (--frames 100000: 0.3 GB, ~5 s).
                   --fps, --speed, --noise and --threads do not apply
  --force          write into a non-empty folder, replacing files of the same names
  --quiet          no progress lines
  --help           this text
)";

struct Options {
  fs::path out;
  SyntheticSequenceConfig config;
  int threads = 0;  ///< 0: OpenCV's default, one per core
  bool force = false;
  bool quiet = false;
  bool points_only = false;
};

Options parse(int argc, char** argv) {
  const CommandLine cli(argc, argv,
                        {"out", "frames", "seed", "width", "height", "fx", "fy", "cx", "cy", "fps",
                         "speed", "noise", "threads", "ring-step", "ring-distance",
                         "ring-elevation", "unit-scale"},
                        {"force", "quiet", "points-only", "no-depth", "help"});
  if (cli.flag("help")) {
    std::cout << kUsage;
    std::exit(0);
  }
  Options o;
  if (!cli.has("out")) throw UsageError("--out DIR is required (see --help)");
  o.out = *cli.text("out");
  if (o.out.empty()) throw UsageError("--out must not be empty");
  SyntheticSequenceConfig& c = o.config;
  c.frames = static_cast<int>(cli.integer("frames", c.frames, 1, 1000000));
  c.seed = static_cast<uint64_t>(cli.integer("seed", 1, 0, 2147483647L));
  const int width = static_cast<int>(cli.integer("width", 640, 8, 8192));
  const int height = static_cast<int>(cli.integer("height", 480, 8, 8192));
  c.intrinsics = syntheticIntrinsics(width, height);
  c.intrinsics.fx = cli.real("fx", c.intrinsics.fx, 1e-3, 1e6);
  c.intrinsics.fy = cli.real("fy", c.intrinsics.fy, 1e-3, 1e6);
  c.intrinsics.cx = cli.real("cx", c.intrinsics.cx, -1e6, 1e6);
  c.intrinsics.cy = cli.real("cy", c.intrinsics.cy, -1e6, 1e6);
  c.fps = cli.real("fps", c.fps, 0.1, 1000.0);
  c.speed = cli.real("speed", c.speed, 0.0, 10.0);
  c.noise_sigma = cli.real("noise", c.noise_sigma, 0.0, 50.0);
  c.ring_step_deg = cli.real("ring-step", 0.0, 0.0, 360.0);
  c.ring_distance = cli.real("ring-distance", c.ring_distance, 1e-3, 10.0);
  c.ring_elevation_deg = cli.real("ring-elevation", c.ring_elevation_deg, -89.0, 89.0);
  c.unit_scale = cli.real("unit-scale", 1.0, 1e-9, 1e9);
  c.write_depth = !cli.flag("no-depth");
  if (c.unit_scale != 1.0 && c.write_depth)
    throw UsageError("--unit-scale needs --no-depth (depth PNGs hold 5000 units a metre)");
  if (c.ring_step_deg == 0.0 && (cli.has("ring-distance") || cli.has("ring-elevation")))
    throw UsageError("--ring-distance and --ring-elevation need --ring-step");
  o.threads = static_cast<int>(cli.integer("threads", 0, 0, 1024));
  o.points_only = cli.flag("points-only");
  if (o.points_only)
    for (const char* name : {"fps", "speed", "noise", "threads", "ring-step", "unit-scale"})
      if (cli.has(name))
        throw UsageError(std::string("--") + name + " does not apply with --points-only");
  o.force = cli.flag("force");
  o.quiet = cli.flag("quiet");
  return o;
}

int runPointsOnly(const Options& o, std::chrono::steady_clock::time_point start) {
  CorridorWalkConfig c;
  c.seed = o.config.seed;
  c.frames = o.config.frames;
  c.intrinsics = o.config.intrinsics;
  const bool tty = isatty(fileno(stderr));
  writeCorridorWalk(o.out.string(), c, [&](size_t done, size_t total) {
    if (o.quiet || (done % 10000 != 0 && done != total)) return;
    std::fprintf(stderr, "%s  keyframe %zu/%zu%s", tty ? "\r" : "", done, total, tty ? "" : "\n");
    if (tty && done == total) std::fprintf(stderr, "\n");
  });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("wrote %d keyframes (points only: %d points each, %.1f m of corridor, seed %llu) to "
              "%s in %.1f s\n",
              c.frames, c.points, c.spacing * (c.frames - 1),
              static_cast<unsigned long long>(c.seed), o.out.c_str(), seconds);
  std::printf("      points.bin groundtruth.txt camera.yaml SOURCE.md\n");
  return 0;
}

int run(const Options& o) {
  std::error_code ec;
  if (fs::exists(o.out, ec)) {
    if (!fs::is_directory(o.out, ec))
      throw IoError("'" + o.out.string() + "' exists and is not a folder");
    if (!fs::is_empty(o.out, ec) && !o.force)
      throw IoError("'" + o.out.string() +
                    "' exists and is not empty; choose another --out or add --force to write "
                    "into it");
  }
  const auto start = std::chrono::steady_clock::now();
  if (o.points_only) return runPointsOnly(o, start);
  if (o.threads > 0) cv::setNumThreads(o.threads);
  const SyntheticSequence sequence(o.config);
  const bool tty = isatty(fileno(stderr));
  auto last = std::chrono::steady_clock::now();
  sequence.writeTumFolder(o.out.string(), [&](size_t done, size_t total) {
    const auto now = std::chrono::steady_clock::now();
    if (o.quiet || (std::chrono::duration<double>(now - last).count() < 1.0 && done != total))
      return;
    last = now;
    std::fprintf(stderr, "%s  frame %zu/%zu%s", tty ? "\r" : "", done, total, tty ? "" : "\n");
    if (tty && done == total) std::fprintf(stderr, "\n");
  });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const SyntheticSequenceConfig& c = sequence.config();
  const PinholeIntrinsics& k = c.intrinsics;
  std::printf(
      "wrote %zu frames (%dx%d, fx %.2f fy %.2f cx %.2f cy %.2f, seed %llu) to %s in %.1f s\n",
      sequence.size(), k.width, k.height, k.fx, k.fy, k.cx, k.cy,
      static_cast<unsigned long long>(c.seed), o.out.c_str(), seconds);
  std::printf("      %s\n", c.write_depth
                                ? "rgb/ depth/ rgb.txt depth.txt groundtruth.txt camera.yaml SOURCE.md"
                                : "rgb/ rgb.txt groundtruth.txt camera.yaml SOURCE.md (no depth)");
  std::printf("scene %zu boxes in a %.1f x %.1f x %.1f m room; ", sequence.scene().boxes().size() - 1,
              c.scene.room_size.x(), c.scene.room_size.y(), c.scene.room_size.z());
  if (c.ring_step_deg > 0.0)
    std::printf("a ring of views %.2f deg apart, %.2f m from the box on the table, %.1f deg above "
                "it; poses in metres x %g\n",
                c.ring_step_deg, c.ring_distance, c.ring_elevation_deg, c.unit_scale);
  else
    std::printf("path %.2f s at %.2f m/s\n", sequence.size() / c.fps, c.speed);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("generate_sequence",
                                        [&] { return run(parse(argc, argv)); });
}
