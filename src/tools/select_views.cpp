// select_views: the whole method offline on a TUM-layout folder. Writes selection.json,
// pairs.txt (COLMAP's match list) and selection.png, and prints a one-screen summary.
#include "command_line.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/pair_announcer.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/eval/nearest_pairs.h"
#include "view_selection/io/export.h"
#include "view_selection/io/params_json.h"
#include "view_selection/io/points_file.h"
#include "view_selection/io/progress.h"
#include "view_selection/io/selection_io.h"
#include "view_selection/io/tum_frames.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/registration/orb_registration.h"
#include "view_selection/session/capture.h"
#include "view_selection/session/journal.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <vector>

namespace fs = std::filesystem;
using namespace view_selection::core;
using namespace view_selection::eval;
using namespace view_selection::io;
using namespace view_selection::points;
using namespace view_selection::session;
using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;

namespace {

const char* kUsage = R"(usage: select_views --dataset DIR [options] [parameters]
       select_views --state FILE [--out DIR] [selection and matrix parameters]

Error-resistant view selection on a TUM RGB-D layout folder (rgb.txt, depth.txt if any,
groundtruth.txt, camera.yaml). Writes selection.json, pairs.txt and selection.png.
A folder with points.bin (generate_sequence --points-only) is read as poses and points alone:
every record is a frame with those points (no images, no depth, so no occlusion test).
The summary gives the time per stage and the peak resident memory (getrusage).
With --state, re-selects the keyframes of a session saved by view_selection_node (~state_file):
the saved parameters, changed by the selection and matrix parameters given (the matrix is
recomputed when a gate changes; keyframe and point-source parameters cannot change).

options:
  --input KIND              auto | collection | stream (default auto). A photo collection keeps
                            every image as a keyframe; a video stream is thinned by the keyframe
                            policy (--keyframe-policy). auto: a collection when the images are
                            at least 0.5 s apart (median), as photos are (DTU, castle: 1 s);
                            a stream otherwise (video at 10-60 Hz). A keyframe option given
                            (--keyframe-policy, --every, ...) applies to either.
  --every N                 every Nth frame becomes a keyframe (--every 1: every frame); short
                            for --keyframe-policy every_nth --every-n N
  --max-frames N            use only the first N associated frames
  --points SOURCE           depth | features | auto (default auto: depth when the folder has
                            depth, else features triangulated with the known poses)
  --no-occlusion            short for --occlusion-test false
  --strategy NAME           ours | nearest (default ours). nearest: each keyframe pairs with
                            its k nearest camera centres within a viewing-angle limit (poses
                            only, no points; writes pairs.txt only)
  --nearest-k N             neighbours per keyframe for nearest (default 5)
  --nearest-max-angle DEG   limit on the angle between optical axes for nearest (default 30)
  --max-time-difference S   rgb/depth/pose association tolerance [s] (default 0.02)
  --out DIR                 output folder (default ./view_selection_output)
  --dump-points             include every keyframe's sample points in selection.json
  --print-sets N            print at most N next view sets (default 40; 0: none)
  --stream-report M[,M...]  replays the pair stream (the node's ~pairs) after every keyframe
                            with each stability rule "announce once still selected M keyframes
                            later" and prints the pairs announced, wasted (announced, not in
                            the final selection) and left for the end (docs/live.md)
  --quiet                   no progress lines (on stderr: one line rewritten in place on a
                            terminal, a line every 10 s into a log or pipe)
  --help                    this text

parameters (the node's ~parameters of the same names, '_' written '-'; defaults shown;
--max-view-angle, --max-parallax and --min-rotation are short for the *-deg ones):
)";

/// Short option names kept from earlier versions and for typing.
const std::map<std::string, std::string> kAliases = {
    {"--max-view-angle", "--max-view-angle-deg"},
    {"--min-rotation", "--min-rotation-deg"},
    {"--max-parallax", "--max-parallax-deg"},
};

/// Peak resident set size of this process so far [MB] (getrusage: ru_maxrss, KiB on Linux).
double peakRssMb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

double seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

struct Options {
  std::string dataset;
  std::string state;  ///< --state FILE
  /// --state: applies the method parameters given on the command line to the saved ones.
  std::function<void(ViewSelectorConfig&)> override_saved;
  fs::path out;
  ViewSelectorConfig config;
  std::string points;
  PointSourceParams point_params;
  long max_frames = 0;
  double max_time_difference = 0.02;
  bool dump_points = false;
  long print_sets = 40;
  bool quiet = false;
  std::vector<int> stream_report;  ///< --stream-report: stability rules to replay
  std::string strategy = "ours";
  NearestPairsConfig nearest;
  std::string input = "auto";      ///< --input: auto | collection | stream
  bool keyframe_options = false;   ///< a keyframe policy option was given
};

/// Median interval between consecutive frames at or above which --input auto takes a folder for a
/// photo collection [s]: photos converted to the TUM layout are stamped seconds apart (their
/// index, or when they were taken), video frames 1/60 to 1/10 s.
constexpr double kCollectionInterval = 0.5;

/// How the frames are taken: a collection (every image a keyframe) or a stream (the policy
/// thins it), and why, for the summary.
struct InputKind {
  bool collection = false;
  std::string why;
};

/// argv with the short aliases replaced by the option names they stand for ("--a=b" too).
std::vector<std::string> expandAliases(int argc, char** argv) {
  std::vector<std::string> args(argv, argv + argc);
  for (size_t q = 1; q < args.size(); ++q) {
    const size_t eq = args[q].find('=');
    const auto it = kAliases.find(args[q].substr(0, eq));
    if (it != kAliases.end())
      args[q] = it->second + (eq == std::string::npos ? "" : args[q].substr(eq));
  }
  return args;
}

/// --stream-report M[,M...]
std::vector<int> streamRules(const CommandLine& cli) {
  std::vector<int> rules;
  if (!cli.has("stream-report")) return rules;
  std::stringstream list(*cli.text("stream-report"));
  for (std::string item; std::getline(list, item, ',');) {
    try {
      const int m = std::stoi(item);
      if (m < 0 || m > 1000) throw std::out_of_range("m");
      rules.push_back(m);
    } catch (const std::exception&) {
      throw UsageError("--stream-report takes keyframe counts 0..1000, e.g. 0,2,4; not '" + item +
                       "'");
    }
  }
  return rules;
}

/// --state FILE: only the options that re-selecting saved keyframes can honour.
Options parseState(const CommandLine& cli, const std::set<std::string>& point_options, Options o) {
  std::set<std::string> refused = {
      "dataset",  "every",     "max-frames",        "points",
      "strategy", "nearest-k", "nearest-max-angle", "max-time-difference"};
  refused.insert(point_options.begin(), point_options.end());
  const std::set<std::string> keyframes =
      view_selection::tools::parameterOptions(KeyframePolicyConfig{});
  refused.insert(keyframes.begin(), keyframes.end());
  for (const std::string& name : refused)
    if (cli.has(name))
      throw UsageError("--" + name +
                       " does not apply with --state (the saved keyframes and their points are "
                       "re-selected as they are)");
  o.state = *cli.text("state");
  const bool no_occlusion = cli.flag("no-occlusion");
  o.override_saved = [cli, no_occlusion](ViewSelectorConfig& config) {
    view_selection::tools::readParameters(cli, config);
    if (no_occlusion) config.matrix.occlusion.enabled = false;
    try {
      config.validate();
    } catch (const InvalidArgument& e) {
      throw UsageError(e.what());
    }
  };
  o.dump_points = cli.flag("dump-points");
  o.print_sets = cli.integer("print-sets", 40, 0, 100000000);
  o.quiet = cli.flag("quiet");
  return o;
}

Options parse(int argc, char** argv) {
  std::set<std::string> options = {
      "dataset", "every",      "max-frames", "points",    "max-time-difference",
      "out",     "print-sets", "strategy",   "nearest-k", "nearest-max-angle",
      "state",   "stream-report", "input"};
  const std::set<std::string> method =
      view_selection::tools::parameterOptions(ViewSelectorConfig{});
  const std::set<std::string> sources =
      view_selection::tools::parameterOptions(PointSourceParams{});
  options.insert(method.begin(), method.end());
  options.insert(sources.begin(), sources.end());
  std::vector<std::string> args = expandAliases(argc, argv);
  std::vector<char*> pointers;
  for (auto& a : args) pointers.push_back(a.data());
  const CommandLine cli(static_cast<int>(pointers.size()), pointers.data(), options,
                        {"dump-points", "no-occlusion", "quiet", "help"});
  if (cli.flag("help")) {
    std::cout << kUsage << view_selection::tools::parameterHelp(ViewSelectorConfig{})
              << view_selection::tools::parameterHelp(PointSourceParams{});
    std::exit(0);
  }
  Options o;
  o.out = cli.text("out", "view_selection_output");
  if (cli.has("state")) return parseState(cli, sources, std::move(o));
  if (!cli.has("dataset"))
    throw UsageError("--dataset DIR or --state FILE is required (see --help)");
  o.dataset = *cli.text("dataset");

  if (cli.has("every") && (cli.has("min-translation") || cli.has("min-rotation-deg") ||
                           cli.has("keyframe-policy") || cli.has("every-n") ||
                           cli.has("keyframe-overlap") || cli.has("keyframe-parallax-deg")))
    throw UsageError(
        "--every and --min-translation/--min-rotation/--keyframe-policy/--every-n/"
        "--keyframe-overlap/--keyframe-parallax-deg exclude each other");
  if (cli.has("no-occlusion") && cli.has("occlusion-test"))
    throw UsageError("--no-occlusion and --occlusion-test exclude each other");
  view_selection::tools::readParameters(cli, o.config);
  view_selection::tools::readParameters(cli, o.point_params);
  if (cli.has("every")) {
    auto& kf = o.config.keyframes;
    kf.every_n = static_cast<int>(cli.integer("every", 1, 1, 1000000));
    kf.mode = kf.every_n == 1 ? KeyframeMode::kEveryFrame : KeyframeMode::kEveryNth;
  }
  if (cli.flag("no-occlusion")) o.config.matrix.occlusion.enabled = false;
  o.input = cli.choice("input", "auto", {"auto", "collection", "stream"});
  for (const char* name : {"every", "keyframe-policy", "every-n", "keyframe-overlap",
                           "keyframe-parallax-deg", "min-translation", "min-rotation-deg"})
    o.keyframe_options = o.keyframe_options || cli.has(name);
  o.max_frames = cli.integer("max-frames", 0, 1, 100000000);
  o.points = cli.choice("points", "auto", {"auto", "depth", "features"});
  o.max_time_difference = cli.real("max-time-difference", o.max_time_difference, 0.0, 10.0);
  o.dump_points = cli.flag("dump-points");
  o.print_sets = cli.integer("print-sets", 40, 0, 100000000);
  o.quiet = cli.flag("quiet");
  o.stream_report = streamRules(cli);
  o.strategy = cli.choice("strategy", "ours", {"ours", "nearest"});
  o.nearest.k = static_cast<int>(cli.integer("nearest-k", o.nearest.k, 1, 1000));
  o.nearest.max_view_angle_deg =
      cli.real("nearest-max-angle", o.nearest.max_view_angle_deg, 0.0, 180.0);
  if (o.strategy != "nearest" && (cli.has("nearest-k") || cli.has("nearest-max-angle")))
    throw UsageError("--nearest-k and --nearest-max-angle need --strategy nearest");
  try {
    o.config.validate();
    o.point_params.validate();
  } catch (const InvalidArgument& e) {
    throw UsageError(e.what());
  }
  return o;
}

std::string percent(double part, double whole) {
  std::ostringstream s;
  s.precision(1);
  s << std::fixed << (whole > 0 ? 100.0 * part / whole : 0.0) << "%";
  return s.str();
}

size_t framesToUse(const Options& o, const TumDataset& dataset) {
  return o.max_frames > 0
             ? std::min<size_t>(dataset.frames.size(), static_cast<size_t>(o.max_frames))
             : dataset.frames.size();
}

struct Timings {
  double read = 0.0, points = 0.0, matrix = 0.0, selection = 0.0, write = 0.0;
  size_t rows_updated = 0;  // earlier keyframes' rows recomputed because their points changed
};

struct StreamReplay;
void addFrames(const Options& o, const TumDataset& dataset, ViewSelector& selector, Timings& t,
               StreamReplay* stream = nullptr);

/// The point source a run on `dataset` uses (--points, auto: depth when the folder has it).
std::unique_ptr<PointSource> pointSourceFor(const Options& o, const TumDataset& dataset) {
  const std::string source =
      o.points == "auto" ? (dataset.has_depth ? "depth" : "features") : o.points;
  if (source == "depth" && !dataset.has_depth)
    throw InvalidInput("'" + o.dataset +
                       "' has no depth (no depth.txt): the depth point source cannot run on it");
  return makePointSource(source, o.point_params, o.config.matrix.occlusion);
}

/// --strategy nearest: the same keyframes (same policy, same frames), paired by pose alone.
int runNearest(const Options& o, const TumDataset& dataset) {
  const size_t total = framesToUse(o, dataset);
  KeyframePolicy policy(o.config.keyframes);
  std::vector<CameraPose> poses;
  std::vector<std::string> names;
  if (policy.needsReference()) {
    // The policy measures against the keyframes' points: the keyframes are those of a full run.
    ViewSelector selector(o.config, pointSourceFor(o, dataset));
    Timings t;
    addFrames(o, dataset, selector, t);
    for (size_t i = 0; i < selector.matrix().size(); ++i) {
      const Keyframe& k = selector.matrix().keyframe(static_cast<ViewId>(i));
      poses.push_back(k.pose);
      names.push_back(k.image_name);
    }
  }
  for (size_t q = 0; q < total && !policy.needsReference(); ++q) {
    const TumFrame& f = dataset.frames[q];
    if (!f.pose.isValid())
      throw InvalidInput("frame " + std::to_string(q) + " (" + f.rgb_path + "): invalid pose");
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
  const double exhaustive =
      poses.size() > 1 ? 0.5 * static_cast<double>(poses.size()) * (poses.size() - 1) : 0.0;
  std::printf("dataset     %s: %zu frames used of %zu in rgb.txt\n", o.dataset.c_str(), total,
              dataset.rgb_entries);
  std::printf("keyframes   %zu (%s)\n", poses.size(), describeKeyframeRule(o.config.keyframes).c_str());
  std::printf("strategy    nearest: k %d, max view angle %.1f deg\n", o.nearest.k,
              o.nearest.max_view_angle_deg);
  std::printf("pairs       %zu to match, exhaustive would be %.0f (%s)\n", pairs.size(), exhaustive,
              percent(static_cast<double>(pairs.size()), exhaustive).c_str());
  std::printf("wrote       %s\n", (o.out / "pairs.txt").c_str());
  return 0;
}

/// --stream-report: the node's pair stream replayed, one announcer per stability rule.
struct StreamReplay {
  std::vector<PairAnnouncer> announcers;
  std::vector<std::set<Pair>> ever;  ///< pairs each announced as added, at any time
  void start(const std::vector<int>& rules, ViewSelector& selector) {
    for (int m : rules) announcers.emplace_back(m);
    ever.resize(rules.size());
    if (!rules.empty()) selector.trackPairChanges(true);
  }
  void keyframe(ViewSelector& selector) {
    if (announcers.empty()) return;
    (void)selector.output();  // the selection after this keyframe, as the node shares it
    const PairChanges changes = selector.takePairChanges();
    for (size_t q = 0; q < announcers.size(); ++q) {
      const Announcement a = announcers[q].update(changes, selector.matrix().size());
      ever[q].insert(a.added.begin(), a.added.end());
    }
  }
  void print(const std::vector<Pair>& final_pairs) {
    if (announcers.empty()) return;
    const std::set<Pair> final_set(final_pairs.begin(), final_pairs.end());
    std::printf("pair stream (announce once still selected M keyframes later; the rest at the end):\n");
    std::printf("  %4s %10s %8s %8s %12s\n", "M", "announced", "wasted", "waste", "at the end");
    for (size_t q = 0; q < announcers.size(); ++q) {
      const Announcement last = announcers[q].flush();  // the recording ended
      ever[q].insert(last.added.begin(), last.added.end());
      size_t wasted = 0;
      for (const Pair& p : ever[q]) wasted += final_set.count(p) ? 0 : 1;
      std::printf("  %4d %10zu %8zu %7.1f%% %12zu\n", announcers[q].stableKeyframes(),
                  ever[q].size(), wasted,
                  ever[q].empty() ? 0.0 : 100.0 * static_cast<double>(wasted) / ever[q].size(),
                  last.added.size());
    }
  }
};

/// Offers every frame to the selector, as the node does with the frames it receives.
void addFrames(const Options& o, const TumDataset& dataset, ViewSelector& selector, Timings& t,
               StreamReplay* stream) {
  const bool features = selector.pointSource().name() == "features";
  // The revisit rule registers frames from their images, as the node does (docs/design.md,
  // "Revisits under drift"): frames that may become keyframes are read with their image.
  const KeyframePolicyConfig& keyframes = selector.config().keyframes;
  const bool registers =
      keyframes.revisit_registration && keyframes.mode == KeyframeMode::kScaleFree;
  if (registers)
    selector.setRegistration(std::make_unique<view_selection::registration::OrbRegistration>());
  const size_t total = framesToUse(o, dataset);
  Progress progress = Progress::toStderr(!o.quiet);
  for (size_t q = 0; q < total; ++q) {
    const auto t0 = std::chrono::steady_clock::now();
    // Frames the policy will skip are passed without depth: reading PNGs is the slow part.
    Frame probe;
    probe.pose = dataset.frames[q].pose;
    probe.intrinsics = dataset.intrinsics;
    probe.stamp = dataset.frames[q].stamp;
    const bool wanted = selector.wantsFrame(probe);
    const Frame frame = loadTumFrame(dataset, dataset.frames[q],
                                     {wanted && !features, wanted && (features || registers)});
    t.read += seconds(t0);
    FrameResult r;
    try {
      r = selector.addFrame(frame);
    } catch (const InvalidInput& e) {
      throw InvalidInput("frame " + std::to_string(q) + " (" + dataset.frames[q].rgb_path +
                         "): " + e.what());
    }
    t.points += r.points_seconds;
    t.rows_updated += r.updated_rows.size();
    t.matrix += r.matrix_seconds;
    if (stream && r.outcome == FrameOutcome::kKeyframe) stream->keyframe(selector);
    progress.report("selecting views", q + 1, total, "frames",
                    std::to_string(selector.matrix().size()) + " keyframes");
  }
  progress.end();
}


void printFeatureStats(const FeaturePointSource& fs, size_t rows_updated) {
  const FeatureStats& t = fs.totalStats();
  const double kf = std::max<double>(1.0, static_cast<double>(t.keyframes));
  std::printf(
      "features    %s, per keyframe (mean of %zu): extract %.1f ms | match %.1f ms | triangulate "
      "%.1f ms (Ceres %.1f)"
      " | %.0f features, %.1f views matched, %.0f matches, %.0f points; %zu earlier rows "
      "recomputed\n",
      fs.config().detector.c_str(), t.keyframes, 1e3 * t.extract_seconds / kf,
      1e3 * t.match_seconds / kf, 1e3 * t.triangulate_seconds / kf, 1e3 * t.refine_seconds / kf,
      t.features / kf, t.candidates / kf, t.matches / kf, t.points / kf, rows_updated);
}

void printSets(const ChunkedSelection& selection, size_t limit) {
  const size_t n = selection.next_views.size();
  if (limit == 0 || n == 0) return;
  std::printf("next view sets (view: C_i best first, + completion):\n");
  const size_t shown = std::min(n, limit);
  for (size_t i = 0; i < shown; ++i) {
    std::printf("  %4zu:", i);
    for (const ViewId j : selection.next_views[i]) std::printf(" %d", j);
    const auto& fin = selection.final_next_views[i];
    for (size_t q = selection.next_views[i].size(); q < fin.size(); ++q)
      std::printf(" +%d", fin[q]);
    std::printf("\n");
  }
  if (shown < n) std::printf("  ... %zu more in selection.json (--print-sets N)\n", n - shown);
}

void printSummary(const Options& o, const TumDataset& dataset, const ViewSelector& selector,
                  const SelectionOutput& snapshot, const ExportResult& written, const Timings& t,
                  double total_seconds) {
  const ErrorResistanceMatrix& matrix = selector.matrix();
  const ChunkedSelection& selection = snapshot.selection;
  const size_t n = matrix.size();
  std::vector<size_t> counts;
  for (const KeyframeSummary& k : snapshot.keyframes) counts.push_back(k.num_points);
  size_t median_points = 0;
  if (!counts.empty()) {
    std::nth_element(counts.begin(),
                     counts.begin() + static_cast<std::ptrdiff_t>(counts.size() / 2), counts.end());
    median_points = counts[counts.size() / 2];
  }
  const double offdiag = n > 1 ? static_cast<double>(n) * (n - 1) : 0.0;
  const double exhaustive = offdiag / 2.0;
  std::printf(
      "dataset     %s: %zu frames used of %zu in rgb.txt (%zu without depth, %zu without pose "
      "dropped)\n",
      o.dataset.c_str(), framesToUse(o, dataset), dataset.rgb_entries,
      dataset.dropped_without_depth, dataset.dropped_without_pose);
  std::printf("intrinsics  %s: fx %.2f fy %.2f cx %.2f cy %.2f, %dx%d\n",
              dataset.intrinsics_source.c_str(), dataset.intrinsics.fx, dataset.intrinsics.fy,
              dataset.intrinsics.cx, dataset.intrinsics.cy, dataset.intrinsics.width,
              dataset.intrinsics.height);
  std::printf("keyframes   %zu (%s), %zu sample points each (median), source: %s\n", n,
              describeKeyframeRule(o.config.keyframes).c_str(), median_points,
              selector.pointSource().name().c_str());
  if (o.config.keyframes.mode == KeyframeMode::kScaleFree)
    std::printf(
        "revisits    %zu frames a new view against the last keyframe, not against an "
        "earlier one near them: no keyframe (%zu of them recognised by registering "
        "their image)\n",
        selector.revisitsSkipped(), selector.revisitsRegistered());
  // The feature source's own line: --points features (auto takes most keyframes from depth).
  if (selector.pointSource().name() == "features")
    if (const FeaturePointSource* fs = featureSourceOf(selector.pointSource()))
      printFeatureStats(*fs, t.rows_updated);
  std::printf("matrix      %zu x %zu, %zu finite entries of %.0f off-diagonal (%s)\n", n, n,
              matrix.table().finiteCount(), offdiag,
              percent(static_cast<double>(matrix.table().finiteCount()), offdiag).c_str());
  std::printf(
      "selection   k %d, completion %s: start view %d, traversal reached %zu, completed %zu, "
      "isolated %zu\n",
      o.config.selection.k, toString(o.config.selection.completion).c_str(), selection.start_view,
      selection.order.size(), selection.completed.size(), selection.isolated.size());
  std::printf("pairs       %zu to match, exhaustive would be %.0f (%s)\n", selection.pairs.size(),
              exhaustive, percent(static_cast<double>(selection.pairs.size()), exhaustive).c_str());
  std::printf(
      "time        read %.2f s | points %.2f s | matrix %.3f s | selection %.4f s | write %.2f s | "
      "total %.2f s\n",
      t.read, t.points, t.matrix, t.selection, t.write, total_seconds);
  std::printf("memory      peak RSS %.0f MB (getrusage ru_maxrss)\n", peakRssMb());
  std::printf("wrote       %s, %s, %s\n", written.selection_json.c_str(), written.pairs_txt.c_str(),
              written.plot_png.c_str());
  printSets(selection, static_cast<size_t>(o.print_sets));
}

/// --state: the saved session's keyframes, re-selected (with the parameters given) and exported.
int runFromState(const Options& o) {
  const auto t_start = std::chrono::steady_clock::now();
  JournalReplay replay;
  const SessionState state = readSession(o.state, &replay);  // with its journal, when there
  if (!replay.error.empty())
    std::fprintf(stderr, "select_views: %s; using the records before it\n", replay.error.c_str());
  const double read_seconds = seconds(t_start);
  std::unique_ptr<ViewSelector> selector = selectorFor(state);
  ViewSelectorConfig config = selector->config();
  o.override_saved(config);
  const auto t_matrix = std::chrono::steady_clock::now();
  selector->setConfig(config);  // recomputes E only when a gate changed
  const double matrix_seconds = seconds(t_matrix);
  const SelectionOutput snapshot = selector->output();
  nlohmann::json params = toJson(*snapshot.params);
  params["source"] = "select_views --state";
  params["state_file"] = o.state;
  params["image_path"] = "";
  ExportOptions options;
  options.title = fs::path(o.state).filename().string() +
                  ", k = " + std::to_string(config.selection.k) +
                  ", completion: " + toString(config.selection.completion);
  options.points = o.dump_points ? &selector->matrix() : nullptr;
  const ExportResult written = exportSelection(o.out.string(), snapshot, params, options);
  const ChunkedSelection& selection = snapshot.selection;
  const size_t n = selector->matrix().size();
  std::printf("state       %s: written by %s, %zu keyframes, %llu frames offered, points: %s\n",
              o.state.c_str(), state.producer.c_str(), n,
              static_cast<unsigned long long>(state.statistics.frames_offered),
              state.points.name.c_str());
  std::printf("matrix      %zu finite entries%s\n", selector->matrix().table().finiteCount(),
              config.matrix == state.selector.config.matrix ? " (as saved)" : " (recomputed)");
  std::printf(
      "selection   k %d, completion %s: start view %d, traversal reached %zu, completed %zu, "
      "isolated %zu\n",
      config.selection.k, toString(config.selection.completion).c_str(), selection.start_view,
      selection.order.size(), selection.completed.size(), selection.isolated.size());
  std::printf("pairs       %zu to match\n", selection.pairs.size());
  std::printf("time        read %.3f s | matrix %.3f s | total %.3f s\n", read_seconds,
              matrix_seconds, seconds(t_start));
  std::printf("wrote       %s, %s, %s\n", written.selection_json.c_str(), written.pairs_txt.c_str(),
              written.plot_png.c_str());
  printSets(selection, static_cast<size_t>(o.print_sets));
  return 0;
}

/// The points of points.bin, handed to the selector for the frame in hand.
class GivenPointSource : public PointSource {
 public:
  std::string name() const override { return "points.bin"; }
  PointSourceResult process(ViewId, const Frame&) override {
    PointSourceResult r;
    r.points = std::move(next_);
    return r;
  }
  void reset() override {}
  void setNext(Eigen::Matrix3Xd points) { next_ = std::move(points); }

 private:
  Eigen::Matrix3Xd next_;
};

/// A points-only folder (points.bin): every record offered as a frame with its points.
/// selection.json, pairs.txt and the plot of a run on o.dataset: `params` (the snapshot's, with
/// what the run adds) get the dataset and frame limit; the plot's title names the set, `what`
/// and the selection parameters.
ExportResult writeOutputs(const Options& o, const ViewSelector& selector,
                          const SelectionOutput& snapshot, nlohmann::json params,
                          const std::string& what) {
  params["dataset"] = o.dataset;
  if (o.max_frames > 0) params["max_frames"] = o.max_frames;
  ExportOptions options;
  options.title = fs::path(o.dataset).filename().string() + what +
                  ", k = " + std::to_string(o.config.selection.k) +
                  ", completion: " + toString(o.config.selection.completion);
  options.points = o.dump_points ? &selector.matrix() : nullptr;
  return exportSelection(o.out.string(), snapshot, params, options);
}

int runPointsOnly(const Options& o, const fs::path& points_file) {
  if (o.strategy == "nearest")
    throw UsageError("--strategy nearest reads rgb.txt; a points.bin folder has none");
  if (o.points != "auto")
    throw UsageError("--points does not apply to a points.bin folder (its points are given)");
  const auto t_start = std::chrono::steady_clock::now();
  PointsFileReader reader(points_file.string());
  auto source = std::make_unique<GivenPointSource>();
  GivenPointSource* given = source.get();
  ViewSelector selector(o.config, std::move(source));
  Timings t;
  const size_t total = o.max_frames > 0 ? std::min<size_t>(reader.size(), size_t(o.max_frames))
                                        : static_cast<size_t>(reader.size());
  Progress progress = Progress::toStderr(!o.quiet);
  PointsRecord record;
  size_t points = 0;
  for (size_t q = 0; q < total; ++q) {
    const auto t0 = std::chrono::steady_clock::now();
    if (!reader.next(record)) break;
    Frame frame;
    frame.stamp = record.stamp;
    char name[64];
    std::snprintf(name, sizeof name, "rgb/%.6f.png", record.stamp);
    frame.image_name = name;
    frame.intrinsics = reader.intrinsics();
    frame.pose = record.pose;
    points += static_cast<size_t>(record.points.cols());
    given->setNext(std::move(record.points));
    t.read += seconds(t0);
    FrameResult r;
    try {
      r = selector.addFrame(frame);
    } catch (const InvalidInput& e) {
      throw InvalidInput("record " + std::to_string(q) + " of " + points_file.string() + ": " +
                         e.what());
    }
    t.points += r.points_seconds;
    t.matrix += r.matrix_seconds;
    if (progress.enabled() && (q % 64 == 0 || q + 1 == total)) {  // getrusage is not free
      char detail[96];
      std::snprintf(detail, sizeof detail, "%zu keyframes, peak RSS %.0f MB", selector.matrix().size(),
                    peakRssMb());
      progress.report("selecting views", q + 1, total, "records", detail);
    }
  }
  progress.end();
  const double rss_matrix = peakRssMb();
  const auto t_sel = std::chrono::steady_clock::now();
  const SelectionOutput snapshot = selector.output();
  t.selection = seconds(t_sel);
  const double rss_selection = peakRssMb();
  const auto t_write = std::chrono::steady_clock::now();
  nlohmann::json params = toJson(*snapshot.params);
  params["image_path"] = "";
  const ExportResult written = writeOutputs(o, selector, snapshot, std::move(params), " (points only)");
  t.write = seconds(t_write);
  const size_t n = selector.matrix().size();
  const ChunkedSelection& selection = snapshot.selection;
  const double offdiag = n > 1 ? static_cast<double>(n) * (n - 1) : 0.0;
  std::printf("dataset     %s: points.bin, %zu records used of %llu (points only)\n",
              o.dataset.c_str(), total, static_cast<unsigned long long>(reader.size()));
  std::printf("keyframes   %zu (%s), %.0f sample points each (mean)\n", n,
              describeKeyframeRule(o.config.keyframes).c_str(),
              total > 0 ? static_cast<double>(points) / static_cast<double>(total) : 0.0);
  std::printf("matrix      %zu finite entries (%.1f a row, %s of the off-diagonal)\n",
              selector.matrix().table().finiteCount(),
              n > 0 ? static_cast<double>(selector.matrix().table().finiteCount()) / n : 0.0,
              percent(static_cast<double>(selector.matrix().table().finiteCount()), offdiag).c_str());
  std::printf(
      "selection   k %d, completion %s: start view %d, traversal reached %zu, completed %zu, "
      "isolated %zu\n",
      o.config.selection.k, toString(o.config.selection.completion).c_str(), selection.start_view,
      selection.order.size(), selection.completed.size(), selection.isolated.size());
  std::printf("pairs       %zu to match\n", selection.pairs.size());
  std::printf(
      "time        read %.2f s | points %.2f s | matrix %.2f s (%.3f ms a keyframe) | selection "
      "%.3f s | write %.2f s | total %.2f s\n",
      t.read, t.points, t.matrix, n > 0 ? 1e3 * t.matrix / static_cast<double>(n) : 0.0,
      t.selection, t.write, seconds(t_start));
  std::printf(
      "memory      peak RSS %.0f MB after the matrix, %.0f MB after the selection, %.0f MB at the "
      "end (getrusage ru_maxrss)\n",
      rss_matrix, rss_selection, peakRssMb());
  std::printf("wrote       %s, %s, %s\n", written.selection_json.c_str(), written.pairs_txt.c_str(),
              written.plot_png.c_str());
  printSets(selection, static_cast<size_t>(o.print_sets));
  return 0;
}

/// --input: a photo collection or a video stream (see the usage), and the keyframe rule that
/// follows: every image of a collection, unless a keyframe option was given.
InputKind inputKind(const Options& o, const TumDataset& dataset, ViewSelectorConfig& config) {
  InputKind kind;
  const size_t total = framesToUse(o, dataset);
  std::vector<double> steps;
  for (size_t q = 1; q < total; ++q)
    steps.push_back(dataset.frames[q].stamp - dataset.frames[q - 1].stamp);
  double median = 0.0;
  if (!steps.empty()) {
    std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2),
                     steps.end());
    median = steps[steps.size() / 2];
  }
  std::ostringstream interval;
  interval.precision(3);
  interval << std::fixed << median;
  if (o.input == "auto") {
    kind.collection = steps.empty() || median >= kCollectionInterval;
    kind.why = std::string(kind.collection ? "a photo collection" : "a video stream") +
               " (--input auto: images " + interval.str() + " s apart, median; " +
               (kind.collection ? "at least " : "under ") + "0.5 s is " +
               (kind.collection ? "a collection)" : "video)");
  } else {
    kind.collection = o.input == "collection";
    kind.why = std::string(kind.collection ? "a photo collection" : "a video stream") +
               " (--input " + o.input + ")";
  }
  if (kind.collection && !o.keyframe_options) {
    config.keyframes.mode = KeyframeMode::kEveryFrame;
    kind.why += ": every image is kept";
  } else if (kind.collection) {
    kind.why += ": thinned by the keyframe options given";
  } else {
    kind.why += ": keyframes by the keyframe policy";
  }
  return kind;
}

/// The summary's account of the frames that did not become keyframes, by name when few.
void printDropped(const Options& o, const TumDataset& dataset, const ViewSelector& selector,
                  const InputKind& kind) {
  const size_t total = framesToUse(o, dataset);
  std::set<std::string> kept;
  const ErrorResistanceMatrix& m = selector.matrix();
  for (size_t i = 0; i < m.size(); ++i)
    kept.insert(m.keyframe(static_cast<ViewId>(i)).image_name);
  std::vector<std::string> dropped;
  for (size_t q = 0; q < total; ++q)
    if (!kept.count(dataset.imageName(dataset.frames[q])))
      dropped.push_back(dataset.frames[q].rgb_path);
  std::printf("input       %s\n", kind.why.c_str());
  if (dropped.empty()) {
    std::printf("dropped     none: every one of the %zu images is a keyframe\n", total);
    return;
  }
  std::printf("dropped     %zu of %zu images, not keyframes by the rule %s", dropped.size(), total,
              describeKeyframeRule(o.config.keyframes).c_str());
  // A collection's dropped photos are named (a user expects each one); a stream's are counted.
  constexpr size_t kNamed = 20;
  if (kind.collection || dropped.size() <= kNamed) {
    std::printf(":");
    for (size_t i = 0; i < dropped.size() && i < kNamed; ++i)
      std::printf(" %s", dropped[i].c_str());
    if (dropped.size() > kNamed) std::printf(" ... (%zu more)", dropped.size() - kNamed);
    if (kind.collection)
      std::printf(" (--input collection without keyframe options keeps every image)");
  }
  std::printf("\n");
}

int run(const Options& given) {
  if (!given.state.empty()) return runFromState(given);
  Options o = given;
  if (const fs::path points = fs::path(o.dataset) / "points.bin"; fs::exists(points))
    return runPointsOnly(o, points);
  const auto t_start = std::chrono::steady_clock::now();
  TumDatasetOptions dataset_options;
  dataset_options.max_time_difference = o.max_time_difference;
  const TumDataset dataset = loadTumDataset(o.dataset, dataset_options);
  const InputKind kind = inputKind(o, dataset, o.config);
  if (o.strategy == "nearest") return runNearest(o, dataset);

  ViewSelector selector(o.config, pointSourceFor(o, dataset));
  Timings t;
  StreamReplay stream;
  stream.start(o.stream_report, selector);
  addFrames(o, dataset, selector, t, &stream);

  const auto t_sel = std::chrono::steady_clock::now();
  const SelectionOutput snapshot = selector.output();
  t.selection = seconds(t_sel);

  const auto t_write = std::chrono::steady_clock::now();
  nlohmann::json params = toJson(*snapshot.params);
  params["max_time_difference"] = o.max_time_difference;
  params["image_path"] = dataset.image_dir;
  const ExportResult written = writeOutputs(o, selector, snapshot, std::move(params), "");
  t.write = seconds(t_write);
  printSummary(o, dataset, selector, snapshot, written, t, seconds(t_start));
  printDropped(o, dataset, selector, kind);
  stream.print(selector.select().pairs);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("select_views", [&] { return run(parse(argc, argv)); });
}
