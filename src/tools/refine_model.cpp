// refine_model: bundle-adjusts a COLMAP model whose cameras sit at SLAM poses (the known-pose
// model): keyframe poses and points refined, intrinsics fixed, a robust loss, outliers filtered.
// colmap_bridge runs it as a process on the model folder, as it runs COLMAP (issue 29).
#include "command_line.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/atomic_file.h"
#include "view_selection/io/colmap_model.h"
#include "view_selection/io/progress.h"
#include "view_selection/refine/model_refinement.h"

#include <glog/logging.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <fstream>
#include <iostream>
#include <optional>
#include <set>
#include <string>

using namespace view_selection;
using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;

namespace {

const char* kUsage = R"(usage: refine_model --input MODEL --output DIR [options]

Refines a COLMAP 3.8 binary model whose images sit at given poses (colmap_bridge's known-pose
model, made by point_triangulator at SLAM poses): the image poses and the 3D points are
bundle-adjusted with the intrinsics fixed, under a robust loss, and observations that reproject
further than --max-error after an adjustment are removed, round after round. An image that would
move further than --max-correction-depth-ratio x the median depth of its points, or turn more
than --max-correction-deg, or that has fewer than --min-observations, keeps its input pose (the
report says why). A solve that fails or raises the cost keeps the whole input model. With every
image movable the result is aligned to the input poses by a similarity, so it stays in their
frame. The output model is always written (the input as is when nothing could be refined: its files
hard-linked where the file system allows).
Cameras must be PINHOLE or SIMPLE_PINHOLE.

  --input MODEL      folder with cameras.bin, images.bin, points3D.bin
  --output DIR       where the refined model is written (created)
  --report FILE      JSON: status, rounds, costs, points and observations before and after,
                     and per image the correction (translation in model units, rotation in deg)
  --matches FILE     the project's verified matches (VSMATCH1: image id, 2D point index, image id,
                     2D point index, as the model's images number their 2D points): after the first
                     adjustment the points are triangulated anew from their tracks at the refined
                     poses, --retriangulations times, each followed by adjustment rounds; matches
                     the drifting poses rejected become points (colmap_bridge writes it from its
                     database)
  --retriangulations N  (default 1)
  --triangulation-max-error PX  a new point drops its worst observation while it is further than
                     this (default 3) in the last triangulation ...
  --triangulation-growth G  ... and this factor more in each earlier one (default 3: 9 px in the
                     first, made at the input poses before the first adjustment)
  --no-triangulate-first  with --matches: the first adjustment on the input's own points
  --no-epipolar      with --matches and priors, the poses are first adjusted to the matches'
                     epipolar geometry (Sampson distances, no points: a long session's drift
                     corrected at the cost of its keyframes), then triangulated; this skips it
  --epipolar-matches-per-pair N  matches of each pair in it (default 8) ...
  --epipolar-loss-scale PX       ... under a Huber loss from PX (default 4) ...
  --epipolar-time-share F        ... within F of the time budget (default 0.3) ...
  --epipolar-iterations N        ... and N Ceres iterations at most (default 100)
  --epipolar-max-blocks N  ... with the images in at most N runs of consecutive ids, each
                     moving rigidly (default 0: every image on its own)
  --rotations FILE   the verified pairs' relative rotations (VSROTAT1: image id, image id, w, x, y, z
                     of the second's world-to-camera rotation relative to the first's): with
                     the priors, the epipolar stage starts from the rotations they and the
                     priors average to, where those turn some image by 5 degrees or more
                     (an odometry's heading drift)
  --no-rotations     the rotations file is read but not used
  --epipolar-only    with --matches: the epipolar stage alone, on the whole budget; the output
                     holds its poses (aligned to the input's) and no points (status epipolar_only)
  --fixed FILE       image names (one a line) that must not move; default: every image moves
  --start MODEL      the poses (by image id) the refinement starts from, e.g. refined while the
                     recording went on: each point moves with the first image of its track; the
                     input's own poses are then the reference (below), and out of time or diverged
                     the model at the start poses is the output
  --reference MODEL  the poses corrections are measured against, the result is aligned to and
                     kept images return to (default: the input's); e.g. the SLAM poses when the
                     input was refined once and re-triangulated
  --loss NAME        cauchy (default), huber, soft_l1, trivial
  --loss-scale PX    where the loss starts to discount an observation (default 1)
  --max-error PX     observations further than this are removed after each round (default 4)
  --min-angle DEG    points with a smaller triangulation angle are removed (default 1.5)
  --rounds N         adjust-and-filter rounds at most (default 4)
  --iterations N     Ceres iterations per round at most (default 100)
  --function-tolerance F  a solve stops when the cost changes by less than F, relative (default 1e-5)
  --min-observations N  images with fewer keep their pose (default 15)
  --max-correction-depth-ratio R  (default 0.5)
  --max-correction-deg DEG        (default 15)
  --max-correction-path-ratio R   ... unless within R x the path the input poses travel (default 0.01) ...
  --max-correction-deg-per-path D ... and D degrees a metre of it (default 0.2): drift grows with the distance
  --prior-translation-ratio R     the given poses' relative motion between consecutive images
                     (by id) is a soft constraint: a step may change by R of its length (1 sigma;
                     default 0.2; 0: no such priors)
  --prior-rotation-deg DEG        ... and turn by DEG (1 sigma; default 3)
  --prior-loss-scale S            Cauchy loss on the priors at S sigmas (default 3)
  --no-align         do not align the result to the input poses
  --max-seconds S    the time the refinement may take, counted from the tool's start (reading the
                     model and the matches included; default 0: no limit): once spent, the solve
                     under way stops at its best state, a triangulation under way is given up,
                     no further round, triangulation or pass begins, and the result is what was
                     reached (status out_of_time; spent before anything was refined: the model as
                     it came). Writing the result comes after it. The report's phase_seconds
                     say where the time went
  --threads N        Ceres threads (default 0: one per core)
  --dense-up-to N    Ceres' dense Schur solver up to N images (default 50), ...
  --sparse-up-to N   ... the sparse one up to N (default 1000), the iterative one above
  --quiet            no summary line
  --no-progress      no progress on stderr (by default: the stage, the rounds or tracks done of
                     the total and the time left; one line rewritten in place on a terminal, a
                     line every --progress-interval seconds into a log or pipe)
  --progress-interval S  (default 10)
  --verbose          Ceres' report of every solve on stderr
  --help             this text
)";

nlohmann::json reportJson(const refine::RefinementReport& r) {
  nlohmann::json images = nlohmann::json::array();
  for (const auto& c : r.images)
    images.push_back({{"image_id", c.image_id},
                      {"name", c.name},
                      {"movable", c.movable},
                      {"refined", c.refined},
                      {"kept", c.kept},
                      {"translation", c.translation},
                      {"rotation_deg", c.rotation_deg},
                      {"centre_input", {c.centre_input.x(), c.centre_input.y(), c.centre_input.z()}},
                      {"centre_refined", {c.centre_refined.x(), c.centre_refined.y(), c.centre_refined.z()}},
                      {"observations_input", c.observations_input},
                      {"observations_refined", c.observations_refined},
                      {"weak", c.weak},
                      {"median_depth", c.median_depth}});
  return {{"status", r.status},
          {"refined", r.refined},
          {"message", r.message},
          {"rounds", r.rounds},
          {"iterations", r.iterations},
          {"passes", r.passes},
          {"retriangulations", r.retriangulations},
          {"epipolar",
           {{"correspondences", r.epipolar_correspondences},
            {"iterations", r.epipolar_iterations},
            {"median_sampson_input", r.epipolar_median_input},
            {"median_sampson_refined", r.epipolar_median_refined},
            {"median_sampson_reference", r.epipolar_median_reference},
            {"undone", r.epipolar_undone},
            {"rotation_pairs", r.rotation_pairs},
            {"rotation_change_deg", r.rotation_change_deg},
            {"rotations_adopted", r.rotations_adopted}}},
          {"not_begun", r.not_begun},
          {"unchanged", r.unchanged},
          {"tracks", r.tracks},
          {"track_conflicts", r.track_conflicts},
          {"initial_cost", r.initial_cost},
          {"final_cost", r.final_cost},
          {"points_input", r.points_input},
          {"points_refined", r.points_refined},
          {"observations_input", r.observations_input},
          {"observations_refined", r.observations_refined},
          {"observations_filtered", r.observations_filtered},
          {"points_filtered", r.points_filtered},
          {"reprojection_error_input", r.reprojection_error_input},
          {"reprojection_error_refined", r.reprojection_error_refined},
          {"aligned", r.aligned},
          {"alignment_scale", r.alignment_scale},
          {"seconds", r.seconds},
          {"phase_seconds", r.phase_seconds},
          {"images", images}};
}

int run(int argc, char** argv) {
  const auto started = std::chrono::steady_clock::now();
  const auto since = [](std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
  };
  // clang-format off
  const CommandLine cli(argc, argv,
                        {"input", "output", "report", "fixed", "reference", "start", "loss", "loss-scale", "max-error",
                         "min-angle", "rounds", "iterations", "min-observations", "max-correction-depth-ratio",
                         "max-correction-deg", "threads", "prior-translation-ratio", "prior-rotation-deg",
                         "prior-loss-scale", "dense-up-to", "function-tolerance", "matches", "retriangulations",
                         "triangulation-max-error", "triangulation-growth", "max-seconds", "sparse-up-to",
                         "progress-interval", "epipolar-matches-per-pair", "epipolar-loss-scale",
                         "epipolar-time-share", "epipolar-iterations", "epipolar-max-blocks",
                         "max-correction-path-ratio", "max-correction-deg-per-path", "rotations"},
                        {"no-align", "quiet", "verbose", "no-triangulate-first", "no-epipolar", "epipolar-only",
                         "no-rotations", "no-progress", "help"});
  // clang-format on
  if (cli.flag("help")) {
    std::cout << kUsage;
    return 0;
  }
  if (!cli.has("input") || !cli.has("output")) throw UsageError("--input and --output are required (see --help)");
  refine::RefinementConfig config;
  config.loss = cli.choice("loss", config.loss, {"cauchy", "huber", "soft_l1", "trivial"});
  config.loss_scale = cli.real("loss-scale", config.loss_scale, 1e-6, 1e6);
  config.max_reprojection_error = cli.real("max-error", config.max_reprojection_error, 1e-6, 1e6);
  config.min_triangulation_angle_deg = cli.real("min-angle", config.min_triangulation_angle_deg, 0.0, 89.0);
  config.max_rounds = static_cast<int>(cli.integer("rounds", config.max_rounds, 1, 100));
  config.max_iterations = static_cast<int>(cli.integer("iterations", config.max_iterations, 1, 10000));
  config.min_observations = static_cast<int>(cli.integer("min-observations", config.min_observations, 0, 1000000));
  config.max_correction_depth_ratio =
      cli.real("max-correction-depth-ratio", config.max_correction_depth_ratio, 1e-9, 1e9);
  config.max_correction_deg = cli.real("max-correction-deg", config.max_correction_deg, 1e-9, 180.0);
  config.max_correction_path_ratio = cli.real("max-correction-path-ratio", config.max_correction_path_ratio, 0.0, 1e6);
  config.max_correction_deg_per_path =
      cli.real("max-correction-deg-per-path", config.max_correction_deg_per_path, 0.0, 1e6);
  config.prior_translation_ratio = cli.real("prior-translation-ratio", config.prior_translation_ratio, 0.0, 1e6);
  config.prior_rotation_deg = cli.real("prior-rotation-deg", config.prior_rotation_deg, 1e-9, 180.0);
  config.prior_loss_scale = cli.real("prior-loss-scale", config.prior_loss_scale, 1e-9, 1e9);
  config.align_to_input = !cli.flag("no-align");
  config.verbose = cli.flag("verbose");
  config.retriangulations = static_cast<int>(cli.integer("retriangulations", config.retriangulations, 0, 100));
  config.triangulation_max_error = cli.real("triangulation-max-error", config.triangulation_max_error, 1e-6, 1e6);
  config.triangulation_growth = cli.real("triangulation-growth", config.triangulation_growth, 1.0, 100.0);
  config.triangulate_first = !cli.flag("no-triangulate-first");
  config.epipolar_first = !cli.flag("no-epipolar");
  config.epipolar_only = cli.flag("epipolar-only");
  config.rotations_first = !cli.flag("no-rotations");
  config.epipolar_matches_per_pair = static_cast<size_t>(
      cli.integer("epipolar-matches-per-pair", static_cast<long>(config.epipolar_matches_per_pair), 1, 100000));
  config.epipolar_loss_scale = cli.real("epipolar-loss-scale", config.epipolar_loss_scale, 1e-6, 1e6);
  config.epipolar_time_share = cli.real("epipolar-time-share", config.epipolar_time_share, 1e-6, 1.0);
  config.epipolar_max_iterations =
      static_cast<int>(cli.integer("epipolar-iterations", config.epipolar_max_iterations, 1, 100000));
  config.epipolar_max_blocks = static_cast<size_t>(
      cli.integer("epipolar-max-blocks", static_cast<long>(config.epipolar_max_blocks), 0, 100000000));
  config.function_tolerance = cli.real("function-tolerance", config.function_tolerance, 1e-12, 0.5);
  config.dense_up_to = static_cast<size_t>(cli.integer("dense-up-to", static_cast<long>(config.dense_up_to), 0, 100000));
  config.threads = static_cast<int>(cli.integer("threads", config.threads, 0, 256));
  config.max_seconds = cli.real("max-seconds", config.max_seconds, 0.0, 1e9);
  config.sparse_up_to = static_cast<size_t>(cli.integer("sparse-up-to", static_cast<long>(config.sparse_up_to), 0, 10000000));

  // The budget covers the whole run: reading the model and the matches too (a 30-minute session's
  // 3.7 million matches take seconds to read and to build tracks from).
  config.budget_start = started;
  io::ColmapModel input = io::readColmapModel(*cli.text("input"));
  std::set<int> movable = refine::allImages(input);
  if (cli.has("fixed")) {
    std::ifstream in(*cli.text("fixed"));
    if (!in) throw core::IoError(*cli.text("fixed") + ": cannot open");
    std::set<std::string> names;
    for (std::string line; std::getline(in, line);)
      if (!line.empty()) names.insert(line);
    for (const auto& [id, im] : input.images)
      if (names.count(im.name)) movable.erase(id);
  }
  refine::RefinementReport report;
  io::ColmapModel reference;
  if (cli.has("reference")) reference = io::readColmapModel(*cli.text("reference"));
  // --start: the refinement begins at those poses, the input's points carried along; the input's
  // own poses are the reference (unless one is given), and "the model as it came" is the started one.
  const bool from_start = cli.has("start");
  if (from_start) {
    if (!cli.has("reference")) reference = input;
    input = refine::startedAt(input, io::readColmapModel(*cli.text("start")));
  }
  std::vector<refine::Match> matches;
  if (cli.has("matches")) matches = refine::readMatches(*cli.text("matches"));
  std::vector<refine::PairRotation> rotations;
  if (cli.has("rotations")) rotations = refine::readPairRotations(*cli.text("rotations"));
  const double reading = since(started);
  io::Progress progress =
      io::Progress::toStderr(!cli.flag("no-progress"), cli.real("progress-interval", io::Progress::kLogInterval, 0.1, 1e6));
  const std::optional<io::ColmapModel> out = refine::refineModelIfChanged(
      input, movable, config, &report, cli.has("reference") || from_start ? &reference : nullptr,
      cli.has("matches") ? &matches : nullptr, &progress,
      cli.has("rotations") ? &rotations : nullptr);
  const auto writing = std::chrono::steady_clock::now();
  // The input as it came (out of time at a 30-minute session's size, a diverged solve): its
  // files linked, not written again (0.5 s there), nor copied.
  if (out)
    io::writeColmapModel(*out, *cli.text("output"));
  else if (from_start || !io::linkColmapModel(*cli.text("input"), *cli.text("output")))
    io::writeColmapModel(input, *cli.text("output"));
  report.phase_seconds["reading"] = reading;
  report.phase_seconds["writing"] = since(writing);
  if (cli.has("report"))
    io::writeAtomically(*cli.text("report"), [&](const std::string& tmp) {
      io::writeFileContents(tmp, reportJson(report).dump(2) + "\n");
    });
  if (!cli.flag("quiet"))
    std::cout << "refine_model: " << report.status << ": " << report.message << "; " << report.points_input
              << " -> " << report.points_refined << " points, reprojection error "
              << report.reprojection_error_input << " -> " << report.reprojection_error_refined << " px, "
              << report.seconds << " s\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  google::InitGoogleLogging(argv[0]);
  FLAGS_minloglevel = google::GLOG_ERROR;  // Ceres' per-step warnings are not the user's business
  return view_selection::tools::runTool("refine_model", [&] { return run(argc, argv); });
}
