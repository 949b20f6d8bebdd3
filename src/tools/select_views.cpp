// select_views: the whole method offline on a TUM-layout folder. Writes selection.json,
// pairs.txt (COLMAP's match list) and selection.png, and prints a one-screen summary.
#include "command_line.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/nearest_pairs.h"
#include "view_selection/core/point_source_factory.h"
#include "view_selection/core/selection_io.h"
#include "view_selection/core/selection_plot.h"
#include "view_selection/core/tum_frames.h"
#include "view_selection/core/view_selector.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>

namespace fs = std::filesystem;
using namespace view_selection;
using tools::CommandLine;
using tools::UsageError;

namespace {

const char* kUsage = R"(usage: select_views --dataset DIR [options]

Error-resistant view selection on a TUM RGB-D layout folder (rgb.txt, depth.txt if any,
groundtruth.txt, camera.yaml). Writes selection.json, pairs.txt and selection.png.

keyframes (default: --min-translation 0.10 --min-rotation 10):
  --every N                 every Nth frame (--every 1: every frame)
  --min-translation M       a new keyframe after M metres (scene units) of motion ...
  --min-rotation DEG        ... or DEG degrees of rotation since the last keyframe
  --max-frames N            use only the first N associated frames
selection:
  --k N                     next view set size (default 5)
  --completion MODE         paper | reachable (default paper)
  --min-covisible-points N  co-visibility gate, points (default 10)
  --min-covisible-ratio R   co-visibility gate, share of X_i (default 0.1)
  --max-view-angle DEG      optional gate on the angle between optical axes (default off)
  --no-occlusion            do not test visibility against keyframe depth maps
strategy (the baseline for comparisons):
  --strategy NAME           ours | nearest (default ours). nearest: each keyframe pairs with
                            its k nearest camera centres within a viewing-angle limit (poses
                            only, no points; writes pairs.txt only)
  --nearest-k N             neighbours per keyframe for nearest (default 5)
  --nearest-max-angle DEG   limit on the angle between optical axes for nearest (default 30)
points:
  --points SOURCE           depth | features | auto (default auto: depth when the folder
                            has depth, else features triangulated with the known poses)
  --features DETECTOR       orb | sift, for --points features (default orb)
  --grid N                  depth sampling grid N x N cells (default 16)
input and output:
  --max-time-difference S   rgb/depth/pose association tolerance [s] (default 0.02)
  --out DIR                 output folder (default ./view_selection_output)
  --dump-points             include every keyframe's sample points in selection.json
  --print-sets N            print at most N next view sets (default 40; 0: none)
  --quiet                   no progress lines
  --help                    this text
)";

double seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

struct Options {
  std::string dataset;
  fs::path out;
  ViewSelectorConfig config;
  std::string points;
  PointSourceParams point_params;
  long max_frames = 0;
  double max_time_difference = 0.02;
  bool dump_points = false;
  long print_sets = 40;
  bool quiet = false;
  std::string strategy = "ours";
  NearestPairsConfig nearest;
};

Options parse(int argc, char** argv) {
  const CommandLine cli(argc, argv,
                        {"dataset", "every", "min-translation", "min-rotation", "max-frames", "k",
                         "completion", "min-covisible-points", "min-covisible-ratio",
                         "max-view-angle", "points", "features", "grid", "max-time-difference", "out",
                         "print-sets", "strategy", "nearest-k", "nearest-max-angle"},
                        {"dump-points", "no-occlusion", "quiet", "help"});
  if (cli.flag("help")) {
    std::cout << kUsage;
    std::exit(0);
  }
  Options o;
  if (!cli.has("dataset")) throw UsageError("--dataset DIR is required (see --help)");
  o.dataset = *cli.text("dataset");
  o.out = cli.text("out", "view_selection_output");

  auto& kf = o.config.keyframes;
  if (cli.has("every") && (cli.has("min-translation") || cli.has("min-rotation")))
    throw UsageError("--every and --min-translation/--min-rotation exclude each other");
  if (cli.has("every")) {
    kf.every_n = static_cast<int>(cli.integer("every", 1, 1, 1000000));
    kf.mode = kf.every_n == 1 ? KeyframeMode::kEveryFrame : KeyframeMode::kEveryNth;
  } else {
    kf.mode = KeyframeMode::kMotion;
    kf.min_translation = cli.real("min-translation", kf.min_translation, 0.0, 1e9);
    kf.min_rotation_deg = cli.real("min-rotation", kf.min_rotation_deg, 0.0, 360.0);
  }
  o.max_frames = cli.integer("max-frames", 0, 1, 100000000);

  o.config.selection.k = static_cast<int>(cli.integer("k", o.config.selection.k, 1, 1000));
  o.config.selection.completion =
      completionModeFromString(cli.choice("completion", "paper", {"paper", "reachable"}));
  auto& m = o.config.matrix;
  m.min_covisible_points =
      static_cast<int>(cli.integer("min-covisible-points", m.min_covisible_points, 1, 1000000));
  m.min_covisible_ratio = cli.real("min-covisible-ratio", m.min_covisible_ratio, 0.0, 1.0);
  m.max_view_angle_deg = cli.real("max-view-angle", m.max_view_angle_deg, 0.0, 180.0);
  o.config.occlusion_test = !cli.flag("no-occlusion");
  o.points = cli.choice("points", "auto", {"auto", "depth", "features"});
  o.point_params.features.detector = cli.choice("features", "orb", {"orb", "sift"});
  const int grid = static_cast<int>(cli.integer("grid", o.config.depth.grid_cols, 1, 256));
  o.config.depth.grid_cols = o.config.depth.grid_rows = grid;
  o.point_params.depth = o.config.depth;
  o.max_time_difference = cli.real("max-time-difference", o.max_time_difference, 0.0, 10.0);
  o.dump_points = cli.flag("dump-points");
  o.print_sets = cli.integer("print-sets", 40, 0, 100000000);
  o.quiet = cli.flag("quiet");
  o.strategy = cli.choice("strategy", "ours", {"ours", "nearest"});
  o.nearest.k = static_cast<int>(cli.integer("nearest-k", o.nearest.k, 1, 1000));
  o.nearest.max_view_angle_deg = cli.real("nearest-max-angle", o.nearest.max_view_angle_deg, 0.0, 180.0);
  if (o.strategy != "nearest" && (cli.has("nearest-k") || cli.has("nearest-max-angle")))
    throw UsageError("--nearest-k and --nearest-max-angle need --strategy nearest");
  return o;
}

std::string percent(double part, double whole) {
  std::ostringstream s;
  s.precision(1);
  s << std::fixed << (whole > 0 ? 100.0 * part / whole : 0.0) << "%";
  return s.str();
}

/// --strategy nearest: the same keyframes (same policy, same frames), paired by pose alone.
int runNearest(const Options& o, const TumDataset& dataset) {
  const size_t total = o.max_frames > 0 ? std::min<size_t>(dataset.frames.size(), static_cast<size_t>(o.max_frames))
                                        : dataset.frames.size();
  KeyframePolicy policy(o.config.keyframes);
  std::vector<CameraPose> poses;
  std::vector<std::string> names;
  for (size_t q = 0; q < total; ++q) {
    const TumFrame& f = dataset.frames[q];
    if (!f.pose.isValid()) throw InvalidInput("frame " + std::to_string(q) + " (" + f.rgb_path + "): invalid pose");
    if (!policy.offer(f.pose)) continue;
    policy.keyframeAccepted(f.pose);
    poses.push_back(f.pose);
    names.push_back(dataset.imageName(f));
  }
  const auto pairs = nearestPairs(poses, o.nearest);
  std::error_code ec;
  fs::create_directories(o.out, ec);
  if (ec) throw IoError("cannot create output folder '" + o.out.string() + "': " + ec.message());
  writePairsTxt((o.out / "pairs.txt").string(), names, pairs);
  const double exhaustive = poses.size() > 1 ? 0.5 * static_cast<double>(poses.size()) * (poses.size() - 1) : 0.0;
  std::printf("dataset     %s: %zu frames used of %zu in rgb.txt\n", o.dataset.c_str(), total, dataset.rgb_entries);
  std::printf("keyframes   %zu\n", poses.size());
  std::printf("strategy    nearest: k %d, max view angle %.1f deg\n", o.nearest.k, o.nearest.max_view_angle_deg);
  std::printf("pairs       %zu to match, exhaustive would be %.0f (%s)\n", pairs.size(), exhaustive,
              percent(static_cast<double>(pairs.size()), exhaustive).c_str());
  std::printf("wrote       %s\n", (o.out / "pairs.txt").c_str());
  return 0;
}

int run(const Options& o) {
  const auto t_start = std::chrono::steady_clock::now();
  TumDatasetOptions dataset_options;
  dataset_options.max_time_difference = o.max_time_difference;
  const TumDataset dataset = loadTumDataset(o.dataset, dataset_options);
  if (o.strategy == "nearest") return runNearest(o, dataset);

  std::string source = o.points == "auto" ? (dataset.has_depth ? "depth" : "features") : o.points;
  if (source == "depth" && !dataset.has_depth)
    throw InvalidInput("'" + o.dataset + "' has no depth (no depth.txt): the depth point source cannot run on it");
  const bool features = source == "features";

  ViewSelector selector(o.config, makePointSource(source, o.point_params));
  const size_t total = o.max_frames > 0 ? std::min<size_t>(dataset.frames.size(), static_cast<size_t>(o.max_frames))
                                        : dataset.frames.size();
  const bool tty = isatty(fileno(stderr));
  double t_read = 0.0, t_points = 0.0, t_matrix = 0.0;
  size_t rows_updated = 0;  // earlier keyframes' rows recomputed because their points changed
  auto last_report = std::chrono::steady_clock::now();
  for (size_t q = 0; q < total; ++q) {
    const auto t0 = std::chrono::steady_clock::now();
    // Frames the policy will skip are passed without depth: reading PNGs is the slow part.
    const bool wanted = selector.wantsFrame(dataset.frames[q].pose);
    const Frame frame = loadTumFrame(dataset, dataset.frames[q], {wanted && !features, wanted && features});
    t_read += seconds(t0);
    FrameResult r;
    try {
      r = selector.addFrame(frame);
    } catch (const InvalidInput& e) {
      throw InvalidInput("frame " + std::to_string(q) + " (" + dataset.frames[q].rgb_path + "): " + e.what());
    }
    t_points += r.points_seconds;
    rows_updated += r.updated_rows.size();
    t_matrix += r.matrix_seconds;
    if (!o.quiet && (seconds(last_report) > 1.0 || q + 1 == total)) {
      last_report = std::chrono::steady_clock::now();
      std::fprintf(stderr, "%s  frame %zu/%zu, %zu keyframes%s", tty ? "\r" : "", q + 1, total,
                   selector.matrix().size(), tty ? "" : "\n");
      if (tty && q + 1 == total) std::fprintf(stderr, "\n");
    }
  }

  const auto t_sel = std::chrono::steady_clock::now();
  const Selection selection = selector.select();
  const double t_selection = seconds(t_sel);

  const auto t_write = std::chrono::steady_clock::now();
  std::error_code ec;
  fs::create_directories(o.out, ec);
  if (ec) throw IoError("cannot create output folder '" + o.out.string() + "': " + ec.message());
  nlohmann::json params = selector.params();
  params["dataset"] = o.dataset;
  params["max_time_difference"] = o.max_time_difference;
  params["image_path"] = dataset.image_dir;
  if (o.max_frames > 0) params["max_frames"] = o.max_frames;
  const ErrorResistanceMatrix& matrix = selector.matrix();
  std::vector<std::string> names;
  for (size_t i = 0; i < matrix.size(); ++i) names.push_back(matrix.keyframe(static_cast<ViewId>(i)).image_name);
  writeSelectionJson((o.out / "selection.json").string(), matrix, selection, params, o.dump_points);
  writePairsTxt((o.out / "pairs.txt").string(), names, selection.pairs);
  writeSelectionPlot((o.out / "selection.png").string(), matrix, selection,
                     fs::path(o.dataset).filename().string() + ", k = " + std::to_string(o.config.selection.k) +
                         ", completion: " + toString(o.config.selection.completion));
  const double t_writing = seconds(t_write);

  // Summary.
  const size_t n = matrix.size();
  std::vector<size_t> counts;
  for (size_t i = 0; i < n; ++i) counts.push_back(static_cast<size_t>(matrix.keyframe(static_cast<ViewId>(i)).points.cols()));
  size_t median_points = 0;
  if (!counts.empty()) {
    std::nth_element(counts.begin(), counts.begin() + static_cast<std::ptrdiff_t>(counts.size() / 2), counts.end());
    median_points = counts[counts.size() / 2];
  }
  const double offdiag = n > 1 ? static_cast<double>(n) * (n - 1) : 0.0;
  const double exhaustive = offdiag / 2.0;
  std::printf("dataset     %s: %zu frames used of %zu in rgb.txt (%zu without depth, %zu without pose dropped)\n",
              o.dataset.c_str(), total, dataset.rgb_entries, dataset.dropped_without_depth,
              dataset.dropped_without_pose);
  std::printf("intrinsics  %s: fx %.2f fy %.2f cx %.2f cy %.2f, %dx%d\n", dataset.intrinsics_source.c_str(),
              dataset.intrinsics.fx, dataset.intrinsics.fy, dataset.intrinsics.cx, dataset.intrinsics.cy,
              dataset.intrinsics.width, dataset.intrinsics.height);
  std::printf("keyframes   %zu (%s), %zu sample points each (median), source: %s\n", n,
              o.config.keyframes.mode == KeyframeMode::kMotion
                  ? ("motion >= " + std::to_string(o.config.keyframes.min_translation).substr(0, 5) + " or " +
                     std::to_string(o.config.keyframes.min_rotation_deg).substr(0, 5) + " deg").c_str()
                  : ("every " + std::to_string(o.config.keyframes.every_n) + " frames").c_str(),
              median_points, selector.pointSource().name().c_str());
  if (const auto* fs = dynamic_cast<const FeaturePointSource*>(&selector.pointSource())) {
    const FeatureStats& t = fs->totalStats();
    const double kf = std::max<double>(1.0, static_cast<double>(t.keyframes));
    std::printf("features    %s, per keyframe (mean of %zu): extract %.1f ms | match %.1f ms | triangulate %.1f ms (Ceres %.1f)"
                " | %.0f features, %.1f views matched, %.0f matches, %.0f points; %zu earlier rows recomputed\n",
                fs->config().detector.c_str(), t.keyframes, 1e3 * t.extract_seconds / kf, 1e3 * t.match_seconds / kf,
                1e3 * t.triangulate_seconds / kf, 1e3 * t.refine_seconds / kf, t.features / kf, t.candidates / kf, t.matches / kf, t.points / kf, rows_updated);
  }
  std::printf("matrix      %zu x %zu, %zu finite entries of %.0f off-diagonal (%s)\n", n, n,
              matrix.table().finiteCount(), offdiag, percent(static_cast<double>(matrix.table().finiteCount()), offdiag).c_str());
  std::printf("selection   k %d, completion %s: start view %d, traversal reached %zu, completed %zu, isolated %zu\n",
              o.config.selection.k, toString(o.config.selection.completion).c_str(), selection.start_view,
              selection.order.size(), selection.completed.size(), selection.isolated.size());
  std::printf("pairs       %zu to match, exhaustive would be %.0f (%s)\n", selection.pairs.size(), exhaustive,
              percent(static_cast<double>(selection.pairs.size()), exhaustive).c_str());
  std::printf("time        read %.2f s | points %.2f s | matrix %.3f s | selection %.4f s | write %.2f s | total %.2f s\n",
              t_read, t_points, t_matrix, t_selection, t_writing, seconds(t_start));
  std::printf("wrote       %s, %s, %s\n", (o.out / "selection.json").c_str(), (o.out / "pairs.txt").c_str(),
              (o.out / "selection.png").c_str());
  if (o.print_sets > 0 && n > 0) {
    std::printf("next view sets (view: C_i best first, + completion):\n");
    const size_t shown = std::min<size_t>(n, static_cast<size_t>(o.print_sets));
    for (size_t i = 0; i < shown; ++i) {
      std::printf("  %4zu:", i);
      for (const ViewId j : selection.next_views[i]) std::printf(" %d", j);
      const auto& fin = selection.final_next_views[i];
      for (size_t q = selection.next_views[i].size(); q < fin.size(); ++q) std::printf(" +%d", fin[q]);
      std::printf("\n");
    }
    if (shown < n) std::printf("  ... %zu more in selection.json (--print-sets N)\n", n - shown);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("select_views", [&] { return run(parse(argc, argv)); });
}
