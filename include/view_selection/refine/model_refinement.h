// Refining a known-pose model (issue 29): the keyframe poses and the 3D points of a COLMAP model
// triangulated at SLAM poses are bundle-adjusted with the intrinsics fixed, under a robust loss,
// and observations that stay far from their points are filtered, round after round. The SLAM's
// relative motion between consecutive keyframes is a soft constraint (drift is an accumulation
// of small relative errors): where the images connect keyframes they decide, where they do not
// (a keyframe without points, a break in the tracks) the keyframes move with their neighbours.
// A keyframe the adjustment would move implausibly far keeps the pose it came with, and the
// report says which and why. A solve that fails, raises the cost or runs away (most
// observations left as outliers) keeps the whole model as it came.
//
// Gauge: when every image may move, the best-observed one is held during the solve and the
// result is then aligned to the input poses by a similarity (Umeyama on the camera centres), so
// the refined model stays in the SLAM world frame, as close to the input poses as the refined
// shape allows. When some images are held fixed, they define the frame and no alignment is made.
#pragma once

#include "view_selection/io/colmap_model.h"
#include "view_selection/io/progress.h"
#include "view_selection/refine/rotation_averaging.h"
#include "view_selection/refine/tracks.h"

#include <chrono>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace view_selection::refine {

struct RefinementConfig {
  /// Robust loss on the reprojection error: cauchy, huber, soft_l1, or trivial (plain squares).
  std::string loss = "cauchy";
  double loss_scale = 1.0;  ///< [px] where the loss starts to discount an observation
  /// [px] after each adjustment, observations reprojecting further than this are removed
  /// (COLMAP's Mapper.filter_max_reproj_error).
  double max_reprojection_error = 4.0;
  /// [deg] points whose widest pair of rays meets at a smaller angle are removed (COLMAP's
  /// Mapper.filter_min_tri_angle): their depth is not determined.
  double min_triangulation_angle_deg = 1.5;
  /// With the project's matches: after the first adjustment, the points are triangulated anew
  /// from the tracks of the matches at the refined poses this many times, each followed by
  /// adjust-then-filter rounds. Matches the drifting poses rejected become observations now
  /// (points triangulated at wrong poses are outliers at the right ones).
  int retriangulations = 1;
  /// [px] an observation further than this from its new point is dropped (the worst first);
  /// tighter than the filter's 4 px, as the live model measured (live/model.py).
  double triangulation_max_error = 3.0;
  /// With triangulate_first the matches are also triangulated before the first adjustment, at
  /// the input poses, admitting triangulation_max_error x growth^retriangulations (9 px): the
  /// drifting poses put far-apart views' observations a few pixels off, and those are what
  /// corrects the drift; the robust loss weighs them as the poses improve, and the last
  /// triangulation holds to triangulation_max_error. Measured on DTU scan24 and the ring with a
  /// 2% drift (dev/benchmark_drift): 4.0 mm and 1.97 mm without, 0.97 mm and 1.18 mm with, in
  /// less time. In general the k-th of n triangulations admits max_error x growth^(n - k).
  double triangulation_growth = 3.0;
  bool triangulate_first = true;
  /// With matches and the priors below: before the first triangulation the poses are adjusted to
  /// the matches' epipolar geometry (epipolar.h: Sampson distances, no points), with at most
  /// epipolar_matches_per_pair matches of each pair of at least epipolar_min_matches, under a
  /// Huber loss at epipolar_loss_scale px (the matches are verified, so a pair far off is drift
  /// to correct, not an outlier to discount), within epipolar_time_share of what is left of the
  /// budget. It is what corrects a long session's drift within a finish's few seconds, where the
  /// bundle adjustment makes a few iterations (issue 34).
  bool epipolar_first = true;
  size_t epipolar_matches_per_pair = 8;
  size_t epipolar_min_matches = 15;
  double epipolar_loss_scale = 4.0;
  double epipolar_time_share = 0.3;
  int epipolar_max_iterations = 100;
  /// At most this many pose blocks in the epipolar stage (0: one an image): with more images
  /// (those not kept), they move in runs of consecutive image ids (a SLAM system's keyframes in
  /// their order), each run rigidly with its first image (a run holding an image the gauge holds
  /// is held), so that its linear solve stays the size of a shorter session's. Its sparse Cholesky factorisation is what grows: 1.3 s an
  /// iteration of the 15.1 s of a 30-minute walk's 7,600 keyframes (docs/live.md). Drift within
  /// a run of consecutive keyframes is what the finish's adjustment corrects.
  size_t epipolar_max_blocks = 0;
  /// Only the epipolar stage, on the whole budget (epipolar_time_share does not apply), needs
  /// the matches and the priors: the poses it reaches, aligned to the input's, the points left
  /// out (RefinementReport::status "epipolar_only"). A long session's drift pulled back while the
  /// recording goes on, at a fraction of an adjustment's cost (0.3 s an iteration at 2,600
  /// keyframes): its poses are where the finish's refinement starts (refinement/background.py).
  /// Alone it has a floor: the pairs' epipolar geometry leaves each step's scale to the priors.
  /// A 10-minute walk's 480 mm came down to 121 mm in 10 iterations; a 30-image arc drifted by
  /// 3.0 mm went to 17 mm (its Sampson distances 2.0 -> 0.24 px). The adjustment after it, from
  /// its poses, reaches what it reaches from the input's (tests).
  bool epipolar_only = false;
  /// With the pairs' relative rotations (refineModel's `rotations`: the two-view geometries'
  /// own, estimated from each pair's matches), the epipolar stage first averages them with the
  /// priors' (rotation_averaging.h) and, where that turns some image by more than
  /// rotation_min_change_deg, starts from the averaged rotations, each step's translation (as the
  /// poses it came with have it, in the camera's frame) chained from the first image: an
  /// odometry's heading drift (140 degrees by the middle of a 30-minute walk) is where the local
  /// stages break the chain of priors, and the global averaging puts every rotation within a few
  /// degrees of the truth (that walk: 53.7 -> 1.0 degrees median, 5.5 at most). Below the
  /// threshold the poses are left as they came: the local stages correct a few degrees, and the
  /// pairs' rotations are noisier than that (2.5 degrees median at QVGA). Only when the caller
  /// holds no image (the averaged frame is then aligned back to the reference at the end), and
  /// under a budget only when half of what the epipolar stage has left pays for it (about 1.5 ms
  /// a keyframe; else "rotations" is not begun): a long session's finish leaves it to the
  /// refinement after it.
  /// A pair's relative rotation counts with rotation_pair_sigma_deg, a prior's with
  /// prior_rotation_deg, each under a Cauchy loss at its sigma.
  bool rotations_first = true;
  double rotation_pair_sigma_deg = 5.0;
  double rotation_min_change_deg = 5.0;
  int rotation_iterations = 10;
  /// [s] what a triangulation of the tracks costs per observation, at the least: under a budget
  /// a triangulation begins only when half of the time left pays for that, and the epipolar
  /// stage only when what its share leaves does (its poses are undone without a triangulation
  /// at them); a step not begun is named in RefinementReport::not_begun. Measured on one core
  /// of the development machine: 1.3 us at 10 minutes (0.65 s, 495,000 observations), 2 us at
  /// 30 (2.2 s, 1.1 million), where a finish spent its budget on two epipolar iterations and a
  /// triangulation given up half-way, then returned the model as it came.
  double triangulation_seconds_per_observation = 1e-6;
  /// Adjust-then-filter rounds; stops earlier when a round filters (almost) nothing.
  int max_rounds = 4;
  int max_iterations = 100;  ///< Ceres iterations per adjustment
  /// Ceres stops when the cost changes by less than this, relative: 1e-5 halves the iterations
  /// of 1e-6 for the same ATE within 1% (DTU, the ring, the walk; dev/benchmark_drift).
  double function_tolerance = 1e-5;
  /// A round that leaves more than this fraction of its observations beyond
  /// max_reprojection_error has run away (diverged): the input model is kept.
  double max_filtered_ratio = 0.5;
  /// Without priors, a movable image with fewer observations than this keeps its input pose:
  /// it cannot be held by so few points. With priors it moves with its neighbours (`weak`).
  int min_observations = 15;
  /// A movable image that the adjustment would move further than this fraction of the median
  /// depth of its points, or turn by more than max_correction_deg, keeps its input pose ...
  double max_correction_depth_ratio = 0.5;
  double max_correction_deg = 15.0;
  /// ... unless it is within these of the path the reference poses travel (by image id): drift
  /// grows with the distance, and a long session's correction is large without being implausible
  /// (a 5-minute walk with the odometry stand-in's poses, 217 m: refined to convergence, its
  /// keyframes moved 0.32 m and turned 12 degrees median, 0.84 m and 20 degrees at most). A
  /// translation up to max_correction_path_ratio x the path, a rotation up to
  /// max_correction_deg_per_path x the path [deg/m], count as plausible.
  double max_correction_path_ratio = 0.01;
  double max_correction_deg_per_path = 0.2;
  /// The SLAM's relative motion between consecutive images (by id) as soft constraints: a
  /// step's translation may change by this fraction of its length (1 sigma; at least this
  /// fraction of a tenth of the median step), its rotation by prior_rotation_deg, under a
  /// Cauchy loss at prior_loss_scale sigmas (a tracking jump is not believed). 0: no priors
  /// (the scale is then held by one translation coordinate, as COLMAP does). They hold what the
  /// images do not connect (a keyframe without points, a break in the tracks) and must not
  /// fight the images where they see: 20% and 3 degrees, chosen on the walk with the odometry
  /// stand-in's poses (3.54 mm at 5% and 1 degree, 3.31 mm at 20% and 3, 3.30 mm without) and
  /// no worse on DTU and the ring (dev/benchmark_drift).
  double prior_translation_ratio = 0.2;
  double prior_rotation_deg = 3.0;
  double prior_loss_scale = 3.0;
  /// With every image movable: align the result to the input poses (Sim(3)); see above.
  bool align_to_input = true;
  /// [s] wall time the refinement may take, 0: no limit. Once it is spent, the solve under way
  /// stops at its best state so far, a triangulation under way is given up (the points stay
  /// what they were; it looks at the clock every 1024 tracks), no further round, triangulation
  /// or pass begins, and the result is what the adjustments reached (status out_of_time; with
  /// no image movable, the model as it came): a live finish's refinement stays within a bound
  /// however long the session was (issue 28). No stage begins once it is spent: a solve's
  /// setup alone costs seconds on a 30-minute session's 600,000 observations.
  double max_seconds = 0.0;
  /// When max_seconds counts from (default, the epoch: refineModel's start). refine_model sets
  /// its own start, so that reading the model and the matches is within the budget.
  std::chrono::steady_clock::time_point budget_start{};
  int threads = 0;  ///< Ceres threads; 0: one per core
  /// Ceres' dense Schur solver up to this many images, the sparse one up to sparse_up_to, the
  /// iterative one (Schur-Jacobi preconditioner) above: COLMAP's bundle adjuster's choice.
  size_t dense_up_to = 50;
  size_t sparse_up_to = 1000;
  bool verbose = false;  ///< Ceres' report of each solve on stderr

  /// Throws core::InvalidArgument naming the bad value.
  void validate() const;
};

/// What happened to one image.
struct ImageCorrection {
  int image_id = 0;
  std::string name;
  bool movable = false;   ///< asked to move
  bool refined = false;   ///< moved by the refinement (false: kept its input pose)
  std::string kept;       ///< why it kept its input pose ("" when refined or not movable)
  double translation = 0.0;   ///< |refined centre - input centre| [model units]
  double rotation_deg = 0.0;  ///< angle of R_refined R_input^T [deg]
  Eigen::Vector3d centre_input = Eigen::Vector3d::Zero();
  Eigen::Vector3d centre_refined = Eigen::Vector3d::Zero();
  int observations_input = 0;
  int observations_refined = 0;
  bool weak = false;  ///< refined with fewer than min_observations: held mostly by the priors
  double median_depth = 0.0;  ///< of its observed points, in the input model [model units]
};

struct RefinementReport {
  /// converged | no_convergence (iterations ran out; the result is still better) | out_of_time
  /// (max_seconds was spent: the result is what the adjustments reached by then) | diverged
  /// (the solve failed, raised the cost, or left more than max_filtered_ratio of the
  /// observations as outliers: the input model is returned) | nothing_to_refine | triangulated
  /// (no image may move, matches given: their tracks triangulated at the given poses)
  std::string status = "nothing_to_refine";
  bool refined = false;  ///< the returned model differs from the input
  int rounds = 0;
  int iterations = 0;  ///< Ceres iterations, all rounds
  int passes = 1;      ///< 2 when implausible corrections made it start again with them held
  int retriangulations = 0;  ///< times the points were triangulated anew from the matches
  /// The epipolar adjustment before the first triangulation (epipolar_first): its correspondences
  /// (0: it did not run), Ceres iterations, and the median |Sampson distance| [px] before and after.
  size_t epipolar_correspondences = 0;
  int epipolar_iterations = 0;
  double epipolar_median_input = 0.0, epipolar_median_refined = 0.0;
  /// With epipolar_only: the median |Sampson distance| [px] of the same matches at the reference
  /// poses (the node's, where the input is an earlier run's): how far off the matches' geometry
  /// the poses the refinement is measured against are.
  double epipolar_median_reference = 0.0;
  /// The rotations' global start (rotations_first): the pairs' relative rotations used (0: it
  /// did not run), the largest turn the averaging gave an image [deg], and whether the stage
  /// started from the averaged rotations (the turn was at least rotation_min_change_deg).
  size_t rotation_pairs = 0;
  double rotation_change_deg = 0.0;
  bool rotations_adopted = false;
  /// Its poses were given up: the budget left no time to triangulate at them, and the model's
  /// points, made at the input poses, were adjusted from those.
  bool epipolar_undone = false;
  /// Steps not begun because the time left would not pay for them ("epipolar", "rotations",
  /// "triangulation", "adjustment"), in the order they were left out.
  std::vector<std::string> not_begun;
  /// The returned model is the input as it came (refine_model then links the input's files into
  /// the output instead of writing them again).
  bool unchanged = false;
  size_t tracks = 0, track_conflicts = 0;  ///< of the matches given, and matches left out
  double initial_cost = 0.0, final_cost = 0.0;  ///< of the last solve [px^2, robust]
  size_t points_input = 0, points_refined = 0;
  size_t observations_input = 0, observations_refined = 0;
  size_t observations_filtered = 0;  ///< removed as outliers, all rounds
  size_t points_filtered = 0;        ///< removed (track too short or angle too small)
  double reprojection_error_input = 0.0;    ///< mean over points of their mean error [px]
  double reprojection_error_refined = 0.0;  ///< the same after refinement [px]
  bool aligned = false;     ///< the result was aligned to the input (every image movable)
  double alignment_scale = 1.0;
  std::string message;      ///< a sentence for the log
  std::vector<ImageCorrection> images;
  double seconds = 0.0;     ///< wall time of refineModel
  /// Wall time [s] by step, both passes together: "setup" (tracks, the epipolar pairs, the
  /// depths), "epipolar", "triangulation", "adjustment", "filter" (and refine_model adds
  /// "reading" and "writing"): where a budget went.
  std::map<std::string, double> phase_seconds;
};

/// The refined model; `movable` are the image ids that may move (others are held fixed).
/// Cameras (intrinsics) are never changed. `reference`, when given, holds the poses that
/// corrections are measured against, the result is aligned to and kept images return to (by
/// image id; e.g. the SLAM poses when `input` was already refined once and re-triangulated);
/// by default the input's. Throws core::InvalidArgument for a camera model other than
/// SIMPLE_PINHOLE or PINHOLE, or non-finite input. `matches` (verified matches of the project
/// as (image id, 2D point index) pairs, the 2D points of the model's images): the points are
/// triangulated anew from them at the refined poses (config.retriangulations); without them
/// the input's points and tracks are refined as they are. `progress`, when given, shows each
/// triangulation's tracks and each adjustment's rounds (and Ceres' iterations) as they go.
/// `rotations`: the verified pairs' relative rotations (config.rotations_first), by image id.
io::ColmapModel refineModel(const io::ColmapModel& input, const std::set<int>& movable,
                            const RefinementConfig& config, RefinementReport* report,
                            const io::ColmapModel* reference = nullptr,
                            const std::vector<Match>* matches = nullptr,
                            io::Progress* progress = nullptr,
                            const std::vector<PairRotation>* rotations = nullptr);

/// refineModel without a copy of a model returned as it came: std::nullopt then
/// (report->unchanged), else the refined model.
std::optional<io::ColmapModel> refineModelIfChanged(
    const io::ColmapModel& input, const std::set<int>& movable, const RefinementConfig& config,
    RefinementReport* report, const io::ColmapModel* reference = nullptr,
    const std::vector<Match>* matches = nullptr, io::Progress* progress = nullptr,
    const std::vector<PairRotation>* rotations = nullptr);

/// Every image id of `model`.
std::set<int> allImages(const io::ColmapModel& model);

/// `model` with each image that `start` holds (by id) at start's pose, and each point moved with
/// the first image of its track (it keeps its place in that image's camera): where a refinement
/// starts from poses refined earlier (refine_model --start; refinement/background.py), the points
/// following them without a triangulation. A point one of whose images moved has its error (the
/// mean reprojection error COLMAP reads) measured again at the new poses; -1 where it cannot be
/// (a camera that is not a pinhole one, the point behind a camera). Throws core::InvalidArgument
/// for a non-finite pose.
io::ColmapModel startedAt(const io::ColmapModel& model, const io::ColmapModel& start);

}  // namespace view_selection::refine
