#include "view_selection/refine/model_refinement.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/eval/trajectory_alignment.h"
#include "view_selection/refine/epipolar.h"
#include "view_selection/refine/tracks.h"
#include "view_selection/refine/triangulation.h"

#include <ceres/ceres.h>
#include <ceres/product_manifold.h>
#include <ceres/rotation.h>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <cstdio>
#include <functional>
#include <thread>

namespace view_selection::refine {

namespace {

constexpr double kPi = 3.14159265358979323846;

double degrees(double rad) { return rad * 180.0 / kPi; }

/// A SIMPLE_PINHOLE (f cx cy) or PINHOLE (fx fy cx cy) camera: what pinhole() reads.
bool isPinhole(const io::ColmapCamera& c) {
  return (c.model_id == 0 && c.params.size() == 3) || (c.model_id == 1 && c.params.size() == 4);
}

/// fx, fy, cx, cy of a SIMPLE_PINHOLE (f cx cy) or PINHOLE (fx fy cx cy) camera.
Eigen::Vector4d pinhole(const io::ColmapCamera& c) {
  if (c.model_id == 0 && isPinhole(c)) return {c.params[0], c.params[0], c.params[1], c.params[2]};
  if (c.model_id == 1 && isPinhole(c)) return {c.params[0], c.params[1], c.params[2], c.params[3]};
  throw core::InvalidArgument("camera " + std::to_string(c.id) +
                              ": refinement supports SIMPLE_PINHOLE and PINHOLE cameras (model id " +
                              std::to_string(c.model_id) + ")");
}

/// The reprojection error of one observation, in pixels; pose as Eigen's quaternion (x, y, z,
/// w in memory) and translation, world to camera.
struct ReprojectionError {
  ReprojectionError(const Eigen::Vector2d& observed, const Eigen::Vector4d& k) : xy(observed), k(k) {}

  /// pose: Eigen's quaternion (x, y, z, w) then the translation, world to camera.
  template <typename T>
  bool operator()(const T* pose, const T* x, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(pose);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(pose + 4), point(x);
    const Eigen::Matrix<T, 3, 1> p = rotation * point + translation;
    residual[0] = T(k[0]) * p.x() / p.z() + T(k[2]) - T(xy.x());
    residual[1] = T(k[1]) * p.y() / p.z() + T(k[3]) - T(xy.y());
    return true;
  }

  Eigen::Vector2d xy;
  Eigen::Vector4d k;
};

/// The SLAM system's relative motion between two keyframes as a soft constraint: the
/// rotation (angle-axis, [rad] / sigma_r) and translation (/ sigma_t) of b relative to a, both
/// world -> camera, against the reference's. Drift is an accumulation of small relative errors,
/// so these priors let the shape bend where the images say so, and hold the parts the images
/// do not connect (a keyframe without points, a break in the tracks) where the SLAM put them.
struct RelativePosePrior {
  RelativePosePrior(const Eigen::Quaterniond& rotation_ba, const Eigen::Vector3d& translation_ba,
                    double sigma_r, double sigma_t)
      : r(rotation_ba), t(translation_ba), sigma_r(sigma_r), sigma_t(sigma_t) {}

  template <typename T>
  bool operator()(const T* a, const T* b, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> ra(a), rb(b);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> pa(a + 4), pb(b + 4);
    const Eigen::Quaternion<T> rba = rb * ra.conjugate();
    const Eigen::Matrix<T, 3, 1> tba = pb - rba * pa;
    const Eigen::Quaternion<T> d = rba * r.cast<T>().conjugate();
    const T wxyz[4] = {d.w(), d.x(), d.y(), d.z()};
    T aa[3];
    ceres::QuaternionToAngleAxis(wxyz, aa);
    for (int k = 0; k < 3; ++k) {
      residual[k] = aa[k] / T(sigma_r);
      residual[3 + k] = (tba[k] - T(t[k])) / T(sigma_t);
    }
    return true;
  }

  Eigen::Quaterniond r;
  Eigen::Vector3d t;
  double sigma_r, sigma_t;
};

/// The state being refined: poses by image id, points by point id, tracks as lists of
/// (image id, 2D index). Images and points of the input are never added to.
struct State {
  struct Pose {
    Eigen::Quaterniond rotation;  ///< world -> camera
    Eigen::Vector3d translation;
    Eigen::Vector3d centre() const { return -(rotation.conjugate() * translation); }
  };
  std::map<int, Pose> poses;
  std::map<int, Eigen::Vector4d> intrinsics;  ///< by image id
  std::map<int, const io::ColmapImage*> images;
  std::map<int64_t, Eigen::Vector3d> points;
  std::map<int64_t, std::vector<io::ColmapTrackElement>> tracks;
  std::map<int64_t, std::array<uint8_t, 3>> colours;

  Eigen::Vector2d observed(const io::ColmapTrackElement& e) const {
    return images.at(e.image_id)->points2D[static_cast<size_t>(e.point2D_idx)].xy;
  }
  /// Reprojection error [px] and depth of point `x` seen by image `image_id`.
  std::pair<double, double> reproject(int image_id, const Eigen::Vector3d& x,
                                      const Eigen::Vector2d& xy) const {
    const Pose& pose = poses.at(image_id);
    const Eigen::Vector4d& k = intrinsics.at(image_id);
    const Eigen::Vector3d p = pose.rotation * x + pose.translation;
    if (!(p.z() > 0.0)) return {std::numeric_limits<double>::infinity(), p.z()};
    const Eigen::Vector2d px(k[0] * p.x() / p.z() + k[2], k[1] * p.y() / p.z() + k[3]);
    return {(px - xy).norm(), p.z()};
  }
  size_t observations() const {
    size_t n = 0;
    for (const auto& [id, t] : tracks) n += t.size();
    return n;
  }
  std::map<int, int> observationsPerImage() const {
    std::map<int, int> n;
    for (const auto& [id, pose] : poses) n[id] = 0;
    for (const auto& [id, t] : tracks)
      for (const auto& e : t) ++n[e.image_id];
    return n;
  }
  double meanError() const {
    double sum = 0.0;
    size_t n = 0;
    for (const auto& [id, t] : tracks) {
      if (t.empty()) continue;
      double e = 0.0;
      for (const auto& o : t) e += reproject(o.image_id, points.at(id), observed(o)).first;
      sum += e / static_cast<double>(t.size());
      ++n;
    }
    return n ? sum / static_cast<double>(n) : 0.0;
  }
};

State stateOf(const io::ColmapModel& model) {
  State s;
  for (const auto& [id, im] : model.images) {
    if (!im.rotation.coeffs().allFinite() || !im.translation.allFinite())
      throw core::InvalidArgument("image " + im.name + " has a non-finite pose");
    s.poses[id] = {im.rotation.normalized(), im.translation};
    s.intrinsics[id] = pinhole(model.cameras.at(im.camera_id));
    s.images[id] = &im;
  }
  for (const auto& [id, p] : model.points) {
    if (!p.xyz.allFinite()) throw core::InvalidArgument("point " + std::to_string(id) + " is not finite");
    s.points[id] = p.xyz;
    s.tracks[id] = p.track;
    s.colours[id] = p.rgb;
  }
  return s;
}

/// Removes observations that reproject further than the limit (unless `by_error` is false) or
/// lie behind their camera, observations of images in `excluded`, then points left with fewer
/// than two observations or a too small triangulation angle. Returns (observations removed,
/// points removed).
std::pair<size_t, size_t> filter(State& s, const RefinementConfig& config, const std::set<int>& excluded,
                                 bool by_error = true) {
  size_t observations = 0, points = 0;
  const double min_angle = config.min_triangulation_angle_deg * kPi / 180.0;
  for (auto it = s.tracks.begin(); it != s.tracks.end();) {
    auto& track = it->second;
    const Eigen::Vector3d& x = s.points.at(it->first);
    const size_t before = track.size();
    track.erase(std::remove_if(track.begin(), track.end(),
                               [&](const io::ColmapTrackElement& e) {
                                 if (excluded.count(e.image_id)) return true;
                                 const auto [error, depth] = s.reproject(e.image_id, x, s.observed(e));
                                 return !(depth > 0.0) || (by_error && !(error <= config.max_reprojection_error));
                               }),
                track.end());
    observations += before - track.size();
    bool keep = track.size() >= 2;
    if (keep && min_angle > 0.0) {
      double widest = 0.0;
      for (size_t a = 0; a < track.size() && widest < min_angle; ++a)
        for (size_t b = a + 1; b < track.size() && widest < min_angle; ++b) {
          const Eigen::Vector3d ra = s.poses.at(track[a].image_id).centre() - x;
          const Eigen::Vector3d rb = s.poses.at(track[b].image_id).centre() - x;
          const double c = ra.normalized().dot(rb.normalized());
          widest = std::max(widest, std::acos(std::clamp(c, -1.0, 1.0)));
        }
      keep = widest >= min_angle;
    }
    if (!keep) {
      observations += track.size();
      s.points.erase(it->first);
      s.colours.erase(it->first);
      it = s.tracks.erase(it);
      ++points;
    } else {
      ++it;
    }
  }
  return {observations, points};
}

std::unique_ptr<ceres::LossFunction> lossOf(const RefinementConfig& c) {
  if (c.loss == "cauchy") return std::make_unique<ceres::CauchyLoss>(c.loss_scale);
  if (c.loss == "huber") return std::make_unique<ceres::HuberLoss>(c.loss_scale);
  if (c.loss == "soft_l1") return std::make_unique<ceres::SoftLOneLoss>(c.loss_scale);
  return nullptr;
}

/// The gauge of a solve: poses of `moving` images change, the others are held; with
/// `scale_image` >= 0 one coordinate (`scale_axis`) of that image's translation is held too,
/// which fixes the scale (COLMAP holds the second image's x the same way).
struct Prior {
  int a = 0, b = 0;
  Eigen::Quaterniond rotation_ba;
  Eigen::Vector3d translation_ba;
  double sigma_r = 0.0, sigma_t = 0.0;
};

struct Gauge {
  std::set<int> moving;
  int scale_image = -1;
  int scale_axis = 0;
  std::vector<Prior> priors;
};

using Clock = std::chrono::steady_clock;

/// The end of the refinement's time budget (max_seconds), or none.
struct Deadline {
  bool set = false;
  Clock::time_point at;
  double left() const { return set ? std::chrono::duration<double>(at - Clock::now()).count() : 1e30; }
  bool passed() const { return set && Clock::now() >= at; }
  /// Half of what is left from now (none stays none).
  Deadline half() const { return share(0.5); }
  /// `fraction` of what is left from now (none stays none).
  Deadline share(double fraction) const {
    Deadline d = *this;
    if (set)
      d.at = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(std::max(0.0, left()) * fraction));
    return d;
  }
};

/// What a bundle adjustment's setup costs per observation [s], about: a stage's first round
/// begins only when the time left (plus a tenth of the budget) pays for it. Measured on one core
/// of the development machine: Ceres' setup and the first step took 4.8-5.5 us an observation
/// (30 minutes: 631,714 observations, 3.0 s; 10 minutes: 600,000, 3.1-3.4 s). Asking for all of
/// that would leave the 10-minute finish unrefined (543 mm) for the sake of 1 s; the first step
/// may overrun the budget, BudgetGuard stops the solve before a second one would.
constexpr double kSolveSecondsPerObservation = 3e-6;

/// An adjustment of the model's own points alone (its matches' triangulation not paid for)
/// begins only when the time left pays for this many times kSolveSecondsPerObservation an
/// observation: its setup and about ten iterations.
constexpr double kAdjustmentAloneSolves = 11.0;

size_t observationsOf(const Tracks& tracks) {
  size_t n = 0;
  for (const auto& t : tracks.tracks) n += t.size();
  return n;
}

/// Whether `share` of the time left, halved (a triangulation's part), pays for triangulating
/// `observations` at config.triangulation_seconds_per_observation (always, without a deadline).
bool triangulationPaidFor(const Deadline& deadline, double share, size_t observations,
                          const RefinementConfig& config) {
  return !deadline.set || deadline.left() * share / 2.0 >=
                              config.triangulation_seconds_per_observation * static_cast<double>(observations);
}

/// Adds the wall time of its scope to `seconds[name]` (the report's phase_seconds).
class PhaseTimer {
 public:
  PhaseTimer(std::map<std::string, double>& seconds, const char* name)
      : seconds_(seconds), name_(name), start_(Clock::now()) {}
  ~PhaseTimer() { seconds_[name_] += std::chrono::duration<double>(Clock::now() - start_).count(); }
  PhaseTimer(const PhaseTimer&) = delete;
  PhaseTimer& operator=(const PhaseTimer&) = delete;

 private:
  std::map<std::string, double>& seconds_;
  const char* name_;
  Clock::time_point start_;
};

/// Tells `on_iteration` each Ceres iteration (for the progress line).
class IterationReporter : public ceres::IterationCallback {
 public:
  explicit IterationReporter(const std::function<void(int)>& on_iteration) : on_iteration_(on_iteration) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    on_iteration_(summary.iteration);
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const std::function<void(int)>& on_iteration_;
};

/// Ends a solve (USER_SUCCESS) once the time left is less than its last iteration took: Ceres
/// looks at its time limit only before an iteration, and one iterative Schur step of a 10-minute
/// session took 1.3 s, so the limit alone overran the budget by up to that.
class BudgetGuard : public ceres::IterationCallback {
 public:
  explicit BudgetGuard(const Deadline& deadline) : deadline_(deadline) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    return deadline_.set && deadline_.left() < summary.iteration_time_in_seconds ? ceres::SOLVER_TERMINATE_SUCCESSFULLY
                                                                                 : ceres::SOLVER_CONTINUE;
  }

 private:
  const Deadline& deadline_;
};

/// One parameter block a pose: Eigen's quaternion (x, y, z, w) and the translation, so that Ceres'
/// Schur eliminator runs its fixed-size <2, 3, 6> kernels.
using PoseBlock = std::array<double, 7>;

PoseBlock poseBlock(const State::Pose& p) {
  return {p.rotation.x(), p.rotation.y(), p.rotation.z(), p.rotation.w(),
          p.translation.x(), p.translation.y(), p.translation.z()};
}

std::map<int, PoseBlock> poseBlocks(const State& s) {
  std::map<int, PoseBlock> blocks;
  for (const auto& [id, p] : s.poses) blocks[id] = poseBlock(p);
  return blocks;
}

/// The poses of `ids` taken back from their blocks after a solve.
void takePoses(State& s, const std::map<int, PoseBlock>& blocks, const std::set<int>& ids) {
  for (int id : ids) {
    const PoseBlock& v = blocks.at(id);
    s.poses[id].rotation = Eigen::Quaterniond(v[3], v[0], v[1], v[2]).normalized();
    s.poses[id].translation = Eigen::Vector3d(v[4], v[5], v[6]);
  }
}

/// A fixed rigid motion applied after a pose block's (world -> camera): x' = q x + t. It moves an
/// image rigidly with the block of the first image of its run (RefinementConfig::epipolar_max_blocks).
struct Offset {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  /// The offset that takes `leader`'s pose to `image`'s: image = offset o leader.
  static Offset between(const State::Pose& image, const State::Pose& leader) {
    Offset d;
    d.q = (image.rotation * leader.rotation.conjugate()).normalized();
    d.t = image.translation - d.q * leader.translation;
    return d;
  }

  /// The pose block `out` of this offset after the block `in` (Eigen's x, y, z, w, then t).
  template <typename T>
  void apply(const T* in, T* out) const {
    const Eigen::Map<const Eigen::Quaternion<T>> r(in);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t_in(in + 4);
    Eigen::Map<Eigen::Quaternion<T>> r_out(out);
    Eigen::Map<Eigen::Matrix<T, 3, 1>> t_out(out + 4);
    const Eigen::Quaternion<T> qd = q.cast<T>();
    r_out = qd * r;
    t_out = qd * t_in + t.cast<T>();
  }

  State::Pose applied(const PoseBlock& block) const {
    PoseBlock out;
    apply(block.data(), out.data());
    return {Eigen::Quaterniond(out[3], out[0], out[1], out[2]).normalized(), Eigen::Vector3d(out[4], out[5], out[6])};
  }
};

/// A residual of two poses (Functor: EpipolarErrors, RelativePosePrior) evaluated on two blocks,
/// each through its image's offset.
template <typename Functor>
struct ThroughOffsets {
  ThroughOffsets(Functor f, const Offset& a, const Offset& b) : f(std::move(f)), a(a), b(b) {}

  template <typename T>
  bool operator()(const T* block_a, const T* block_b, T* residuals) const {
    T pose_a[7], pose_b[7];
    a.apply(block_a, pose_a);
    b.apply(block_b, pose_b);
    return f(pose_a, pose_b, residuals);
  }

  Functor f;
  Offset a, b;
};

/// What every solve here shares: at most `iterations`, the function tolerance, stopped at the
/// deadline (however briefly, it runs), the configured threads (0: one per core), silent.
ceres::Solver::Options solverOptions(const RefinementConfig& config, const Deadline& deadline, int iterations) {
  ceres::Solver::Options options;
  options.max_num_iterations = iterations;
  options.function_tolerance = config.function_tolerance;
  if (deadline.set) options.max_solver_time_in_seconds = std::max(0.01, deadline.left());
  options.num_threads = config.threads > 0 ? config.threads
                                           : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  options.logging_type = ceres::SILENT;
  return options;
}

/// One bundle adjustment of the poses the gauge lets move, and every point; `on_iteration`, when
/// given, is told each iteration.
ceres::Solver::Summary adjust(State& s, const Gauge& gauge, const RefinementConfig& config, const Deadline& deadline,
                              const std::function<void(int)>* on_iteration = nullptr) {
  const std::set<int>& moving = gauge.moving;
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  const std::unique_ptr<ceres::LossFunction> loss = lossOf(config);
  std::map<int, PoseBlock> pose = poseBlocks(s);
  std::set<int> used;
  for (auto& [id, track] : s.tracks)
    for (const auto& e : track) {
      auto* cost = new ceres::AutoDiffCostFunction<ReprojectionError, 2, 7, 3>(
          new ReprojectionError(s.observed(e), s.intrinsics.at(e.image_id)));
      problem.AddResidualBlock(cost, loss.get(), pose[e.image_id].data(), s.points[id].data());
      used.insert(e.image_id);
    }
  ceres::CauchyLoss prior_loss(config.prior_loss_scale);
  for (const Prior& p : gauge.priors) {
    auto* cost = new ceres::AutoDiffCostFunction<RelativePosePrior, 6, 7, 7>(
        new RelativePosePrior(p.rotation_ba, p.translation_ba, p.sigma_r, p.sigma_t));
    problem.AddResidualBlock(cost, &prior_loss, pose[p.a].data(), pose[p.b].data());
    used.insert(p.a);
    used.insert(p.b);
  }
  using PoseManifold = ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>;
  using ScaleHeldManifold = ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::SubsetManifold>;
  for (int id : used) {
    if (!moving.count(id)) {
      problem.SetManifold(pose[id].data(), new PoseManifold);
      problem.SetParameterBlockConstant(pose[id].data());
    } else if (id == gauge.scale_image) {
      problem.SetManifold(pose[id].data(), new ScaleHeldManifold(ceres::EigenQuaternionManifold(),
                                                                 ceres::SubsetManifold(3, {gauge.scale_axis})));
    } else {
      problem.SetManifold(pose[id].data(), new PoseManifold);
    }
  }
  ceres::Solver::Options options = solverOptions(config, deadline, config.max_iterations);
  // As COLMAP's bundle adjuster chooses: dense, sparse, then iterative Schur (a room walked for 10
  // minutes, 3,253 images seeing each other's points: one sparse Schur step took 58 s).
  if (used.size() <= config.dense_up_to) {
    options.linear_solver_type = ceres::DENSE_SCHUR;
  } else if (used.size() <= config.sparse_up_to) {
    options.linear_solver_type = ceres::SPARSE_SCHUR;
  } else {
    options.linear_solver_type = ceres::ITERATIVE_SCHUR;
    options.preconditioner_type = ceres::SCHUR_JACOBI;
  }
  std::unique_ptr<IterationReporter> reporter;
  if (on_iteration) {
    reporter = std::make_unique<IterationReporter>(*on_iteration);
    options.callbacks.push_back(reporter.get());
  }
  BudgetGuard guard(deadline);
  options.callbacks.push_back(&guard);
  ceres::Solver::Summary summary;
  if (problem.NumResidualBlocks() == 0) return summary;
  ceres::Solve(options, &problem, &summary);
  if (config.verbose) std::fprintf(stderr, "%s\n", summary.FullReport().c_str());
  takePoses(s, pose, used);
  return summary;
}

/// Median depth of the points each image observes in `s`, by image id.
std::map<int, double> medianDepths(const State& s) {
  std::map<int, std::vector<double>> depths;
  for (const auto& [id, pose] : s.poses) depths[id];
  for (const auto& [pid, track] : s.tracks)
    for (const auto& e : track)
      depths[e.image_id].push_back(s.reproject(e.image_id, s.points.at(pid), s.observed(e)).second);
  std::map<int, double> out;
  std::vector<double> all;
  for (auto& [id, d] : depths) {
    if (d.empty()) continue;
    std::nth_element(d.begin(), d.begin() + static_cast<long>(d.size() / 2), d.end());
    out[id] = d[d.size() / 2];
    all.push_back(out[id]);
  }
  // An image without points takes the median over the images (the scene's depth).
  std::sort(all.begin(), all.end());
  for (const auto& [id, d] : depths)
    if (d.empty()) out[id] = all.empty() ? 0.0 : all[all.size() / 2];
  return out;
}

double rotationBetweenDeg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return degrees(a.angularDistance(b));
}

/// Applies x -> scale R x + t to every pose and point of `s`.
void transform(State& s, const eval::SimilarityTransform& sim) {
  const Eigen::Quaterniond r(sim.rotation);
  for (auto& [id, pose] : s.poses) {
    const Eigen::Vector3d centre = sim.apply(pose.centre());
    pose.rotation = (pose.rotation * r.conjugate()).normalized();
    pose.translation = -(pose.rotation * centre);
  }
  for (auto& [id, x] : s.points) x = sim.apply(x);
}

/// The gauge: the caller's fixed images are held. With fewer than two of them observed, the
/// best-observed moving image is held too (when none is fixed), and one translation
/// coordinate of the moving image that shares the most points with a held one, along the
/// baseline's largest component in its own frame, fixes the scale.
Gauge gaugeOf(const State& s, const std::map<int, State::Pose>& reference, const std::set<int>& movable,
              const std::set<int>& kept, const RefinementConfig& config) {
  Gauge g;
  for (int id : movable)
    if (!kept.count(id) && s.poses.count(id)) g.moving.insert(id);
  const std::map<int, int> observations = s.observationsPerImage();
  // Priors between consecutive images (by id: the order keyframes were accepted, or photos taken)
  // that take part, from the reference poses. A step's translation sigma is a fraction of its
  // length, but not below that fraction of a tenth of the median step (a camera standing still).
  if (config.prior_translation_ratio > 0.0) {
    std::vector<int> chain;
    for (const auto& [id, pose] : s.poses)
      if (!kept.count(id)) chain.push_back(id);
    std::vector<double> steps;
    for (size_t k = 1; k < chain.size(); ++k)
      steps.push_back((reference.at(chain[k]).centre() - reference.at(chain[k - 1]).centre()).norm());
    std::vector<double> sorted = steps;
    std::sort(sorted.begin(), sorted.end());
    const double median_step = sorted.empty() ? 0.0 : sorted[sorted.size() / 2];
    for (size_t k = 1; k < chain.size(); ++k) {
      const double length = std::max(steps[k - 1], 0.1 * median_step);
      if (!(length > 0.0)) continue;
      Prior p;
      p.a = chain[k - 1];
      p.b = chain[k];
      const State::Pose& a = reference.at(p.a);
      const State::Pose& b = reference.at(p.b);
      p.rotation_ba = (b.rotation * a.rotation.conjugate()).normalized();
      p.translation_ba = b.translation - p.rotation_ba * a.translation;
      p.sigma_r = config.prior_rotation_deg * kPi / 180.0;
      p.sigma_t = config.prior_translation_ratio * length;
      g.priors.push_back(p);
    }
  }
  std::set<int> held;
  for (const auto& [id, n] : observations)
    if (n > 0 && !movable.count(id)) held.insert(id);
  if (held.size() >= 2 || g.moving.empty()) return g;
  if (held.empty()) {
    int best = *g.moving.begin();
    for (int id : g.moving)
      if (observations.at(id) > observations.at(best)) best = id;
    g.moving.erase(best);
    held.insert(best);
  }
  if (!g.priors.empty()) return g;  // the priors' step lengths fix the scale
  const int anchor = *held.begin();
  std::map<int, int> shared;
  for (const auto& [pid, track] : s.tracks) {
    const bool seen = std::any_of(track.begin(), track.end(), [&](const auto& e) { return e.image_id == anchor; });
    if (!seen) continue;
    for (const auto& e : track)
      if (g.moving.count(e.image_id)) ++shared[e.image_id];
  }
  int second = -1, most = 0;
  for (const auto& [id, n] : shared)
    if (n > most) {
      most = n;
      second = id;
    }
  if (second < 0) return g;
  const State::Pose& a = s.poses.at(anchor);
  const State::Pose& b = s.poses.at(second);
  const Eigen::Vector3d baseline = b.rotation * (a.centre() - b.centre());  // in the second's frame
  if (!(baseline.norm() > 0.0)) return g;
  baseline.cwiseAbs().maxCoeff(&g.scale_axis);
  g.scale_image = second;
  return g;
}

/// The points of `tracks` triangulated anew at the poses of `s` (images in `excluded` and their
/// observations left out), replacing its points, by the package's one triangulation
/// (triangulation.h, the live model's too) with `max_error` and min_triangulation_angle_deg.
/// A point takes the colour of an old point that shared an observation.
/// Returns false, with `s` untouched, when `deadline` passed before every track was done
/// (looked at before the first track and every 1024th after it).
/// `progress`, when given, shows the tracks done under `label`.
bool retriangulate(State& s, const Tracks& tracks, const std::set<int>& excluded, const RefinementConfig& config,
                   double max_error, const Deadline& deadline, io::Progress* progress = nullptr,
                   const std::string& label = "triangulating") {
  std::map<std::pair<int, int>, int64_t> old_point;  // (image, 2D index) -> old point id
  for (const auto& [id, track] : s.tracks)
    for (const auto& e : track) old_point[{e.image_id, e.point2D_idx}] = id;
  std::map<int64_t, Eigen::Vector3d> points;
  std::map<int64_t, std::vector<io::ColmapTrackElement>> new_tracks;
  std::map<int64_t, std::array<uint8_t, 3>> colours;
  TriangulationRule rule;
  rule.max_error_px = max_error;
  rule.min_angle_deg = config.min_triangulation_angle_deg;
  int64_t next = 1;
  size_t done = 0;
  for (const auto& track : tracks.tracks) {
    if (done % 1024 == 0) {
      if (deadline.passed()) return false;
      if (progress && done > 0) progress->report(label, done, tracks.tracks.size(), "tracks");
    }
    ++done;
    std::vector<io::ColmapTrackElement> obs;
    for (const Observation& o : track) {
      const auto im = s.images.find(o.image_id);
      if (im == s.images.end() || excluded.count(o.image_id) || o.point2D_idx < 0 ||
          static_cast<size_t>(o.point2D_idx) >= im->second->points2D.size())
        continue;
      obs.push_back({o.image_id, o.point2D_idx});
    }
    std::vector<TrackObservation> rays;
    rays.reserve(obs.size());
    for (const auto& e : obs) {
      const State::Pose& pose = s.poses.at(e.image_id);
      rays.push_back({pose.rotation.toRotationMatrix(), pose.translation, s.intrinsics.at(e.image_id), s.observed(e)});
    }
    const TriangulatedPoint point = triangulateTrack(rays, rule);
    if (!point.ok) continue;
    const Eigen::Vector3d& x = point.x;
    std::vector<io::ColmapTrackElement> kept;
    for (const int q : point.inliers) kept.push_back(obs[static_cast<size_t>(q)]);
    obs = std::move(kept);
    const int64_t id = next++;
    points[id] = x;
    colours[id] = {{128, 128, 128}};
    for (const auto& e : obs) {
      const auto old = old_point.find({e.image_id, e.point2D_idx});
      if (old != old_point.end() && s.colours.count(old->second)) {
        colours[id] = s.colours.at(old->second);
        break;
      }
    }
    new_tracks[id] = std::move(obs);
  }
  s.points = std::move(points);
  s.tracks = std::move(new_tracks);
  s.colours = std::move(colours);
  if (progress) progress->end();
  return true;
}

struct PassResult {
  State state;
  bool diverged = false;
  std::string why;
  int rounds = 0, iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;
  bool converged = true;
  bool out_of_time = false;  ///< the deadline passed: rounds, triangulations or a solve were cut short
  size_t observations_filtered = 0, points_filtered = 0;
  bool aligned = false;
  double scale = 1.0;
  int retriangulations = 0;
  size_t epipolar_correspondences = 0;
  int epipolar_iterations = 0;
  double epipolar_median_input = 0.0, epipolar_median_refined = 0.0;
  bool epipolar_undone = false;
  size_t rotation_pairs = 0;
  double rotation_change_deg = 0.0;
  bool rotations_adopted = false;
  std::vector<std::string> not_begun;  ///< RefinementReport::not_begun
  std::map<std::string, double> seconds;  ///< by step (RefinementReport::phase_seconds)
};

/// Where a pass is, for the progress lines: "(pass 1, stage 2 of 3)".
std::string stageName(int pass_number, int stage, int stages) {
  return "(pass " + std::to_string(pass_number) + ", stage " + std::to_string(stage + 1) + " of " +
         std::to_string(stages) + ")";
}

/// The median |Sampson distance| [px] of the pairs' matches at the poses of `s`.
double medianSampson(const State& s, const std::vector<const EpipolarPair*>& pairs) {
  std::vector<double> d;
  for (const EpipolarPair* p : pairs) {
    const PoseBlock pa = poseBlock(s.poses.at(p->a)), pb = poseBlock(s.poses.at(p->b));
    std::vector<double> r(p->rays_a.size());
    const EpipolarErrors errors(*p);
    errors(pa.data(), pb.data(), r.data());
    for (double v : r) d.push_back(std::abs(v));
  }
  if (d.empty()) return 0.0;
  std::nth_element(d.begin(), d.begin() + static_cast<long>(d.size() / 2), d.end());
  return d[d.size() / 2];
}

/// What the rotations' global start costs a keyframe [s], about (measured on one core of the
/// development machine; it grows faster than the keyframes where revisits join far-apart ones).
constexpr double kRotationSecondsPerImage = 1.5e-3;

/// The rotations' global start (RefinementConfig::rotations_first; rotation_averaging.h): the
/// priors' relative rotations and the pairs' averaged, with the first image of the priors' chain
/// held; where that turns some image by rotation_min_change_deg or more, every image of the chain
/// takes its averaged rotation and its centre is chained again from the first one's, each step
/// the one the poses it came with make, in the camera's frame before the step. Only the images
/// of the priors' chain take part (images kept out of a pass are not in it).
void rotationStart(PassResult& r, const Gauge& gauge, const std::vector<PairRotation>& pairs,
                   const RefinementConfig& config) {
  State& s = r.state;
  if (gauge.priors.empty()) return;
  const PhaseTimer timer(r.seconds, "rotations");
  std::map<int, Eigen::Quaterniond> start;
  std::vector<RelativeRotation> relatives;
  for (const Prior& p : gauge.priors) {
    start[p.a] = s.poses.at(p.a).rotation;
    start[p.b] = s.poses.at(p.b).rotation;
    relatives.push_back({p.a, p.b, p.rotation_ba, p.sigma_r});
  }
  const double pair_sigma = config.rotation_pair_sigma_deg * kPi / 180.0;
  for (const PairRotation& p : pairs)
    if (start.count(p.a) && start.count(p.b)) {
      relatives.push_back({p.a, p.b, p.rotation_ba, pair_sigma});
      ++r.rotation_pairs;
    }
  if (r.rotation_pairs == 0) return;
  const int first = gauge.priors.front().a;
  const RotationAveragingResult averaged =
      averageRotations(start, relatives, first, config.rotation_iterations);
  if (!averaged.solved) return;
  for (const auto& [id, q] : averaged.rotations)
    r.rotation_change_deg = std::max(r.rotation_change_deg, rotationBetweenDeg(q, start.at(id)));
  if (r.rotation_change_deg < config.rotation_min_change_deg) return;
  r.rotations_adopted = true;
  std::map<int, State::Pose> chained;
  const auto placed = [&](int id, const Eigen::Vector3d& centre) {
    const Eigen::Quaterniond q = averaged.rotations.at(id);
    chained[id] = {q, -(q * centre)};
  };
  placed(first, s.poses.at(first).centre());
  for (const Prior& p : gauge.priors) {  // consecutive images, in order
    const State::Pose& a = s.poses.at(p.a);
    const Eigen::Vector3d step =
        a.rotation * (s.poses.at(p.b).centre() - a.centre());  // in a's frame
    placed(p.b, chained.at(p.a).centre() + averaged.rotations.at(p.a).conjugate() * step);
  }
  for (const auto& [id, pose] : chained) s.poses[id] = pose;
}

/// The poses of the gauge's moving images adjusted to the matches' epipolar geometry and the
/// priors, before the first triangulation (epipolar.h; config.epipolar_first). Needs the priors:
/// they alone hold the scale. Images in `kept` and their pairs take no part. A pair's matches are
/// one residual block under a Huber loss on their root mean square (a pair verified with a wrong
/// geometry weighs as one, however many matches it has). A solve that fails leaves the poses as
/// they were; the points are left where they are (the stage after triangulates them anew).
void epipolarStage(PassResult& r, const Gauge& gauge, const std::vector<EpipolarPair>& all,
                   const std::set<int>& kept, const RefinementConfig& config,
                   const Deadline& deadline, const std::string& where, io::Progress* progress,
                   const std::vector<PairRotation>* rotations, bool all_movable) {
  State& s = r.state;
  const PhaseTimer timer(r.seconds, "epipolar");
  std::vector<const EpipolarPair*> pairs;
  for (const auto& p : all)
    if (!kept.count(p.a) && !kept.count(p.b) && s.poses.count(p.a) && s.poses.count(p.b) &&
        (gauge.moving.count(p.a) || gauge.moving.count(p.b)))
      pairs.push_back(&p);
  if (pairs.empty() || gauge.priors.empty() || gauge.moving.empty()) return;
  for (const EpipolarPair* p : pairs) r.epipolar_correspondences += p->rays_a.size();
  r.epipolar_median_input = medianSampson(s, pairs);
  const std::map<int, State::Pose> incoming = s.poses;
  if (config.rotations_first && rotations && all_movable) {
    // Not under a budget it would take half of: 0.6 s at 941 keyframes, 2.2 s at 1,521 (the
    // factorisation fills in where revisits join far-apart keyframes), about 1.5 ms a keyframe.
    if (deadline.left() >=
        2.0 * kRotationSecondsPerImage * static_cast<double>(gauge.moving.size() + 1))
      rotationStart(r, gauge, *rotations, config);
    else
      r.not_begun.push_back("rotations");
  }
  ceres::Problem problem;  // owns the cost functions and the pairs' losses
  ceres::CauchyLoss* prior_loss = new ceres::CauchyLoss(config.prior_loss_scale);
  std::map<int, PoseBlock> pose = poseBlocks(s);
  // With more images than epipolar_max_blocks, the images in runs of consecutive ids: each run
  // moves rigidly with one block (`leader`: its first image, or the one the gauge holds, which
  // then holds the run), so a pair or a prior within one run is constant and left out.
  // Otherwise every image is its own block.
  std::map<int, int> leader;
  std::map<int, Offset> offset;
  std::vector<int> images;
  for (const auto& [id, p] : s.poses)
    if (!kept.count(id)) images.push_back(id);
  const bool grouped = config.epipolar_max_blocks > 0 && images.size() > config.epipolar_max_blocks;
  if (grouped) {
    const size_t run = (images.size() + config.epipolar_max_blocks - 1) / config.epipolar_max_blocks;
    for (size_t begin = 0; begin < images.size(); begin += run) {
      const size_t end = std::min(images.size(), begin + run);
      int first = images[begin];
      for (size_t k = begin; k < end; ++k)
        if (!gauge.moving.count(images[k])) {
          first = images[k];
          break;
        }
      for (size_t k = begin; k < end; ++k) {
        leader[images[k]] = first;
        offset[images[k]] = Offset::between(s.poses.at(images[k]), s.poses.at(first));
      }
    }
  }
  const auto blockOf = [&](int id) {
    const auto it = leader.find(id);
    return it == leader.end() ? id : it->second;
  };
  const auto offsetOf = [&](int id) {
    const auto it = offset.find(id);
    return it == offset.end() ? Offset() : it->second;
  };
  std::set<int> used;
  for (const EpipolarPair* p : pairs) {
    const int n = static_cast<int>(p->rays_a.size());
    const int a = blockOf(p->a), b = blockOf(p->b);
    if (a == b) continue;
    ceres::CostFunction* cost = nullptr;
    if (grouped)
      cost = new ceres::AutoDiffCostFunction<ThroughOffsets<EpipolarErrors>, ceres::DYNAMIC, 7, 7>(
          new ThroughOffsets<EpipolarErrors>(EpipolarErrors(*p), offsetOf(p->a), offsetOf(p->b)), n);
    else
      cost = new ceres::AutoDiffCostFunction<EpipolarErrors, ceres::DYNAMIC, 7, 7>(new EpipolarErrors(*p), n);
    // Huber on the block's sum of squares: quadratic while the pair's RMS is within the scale.
    problem.AddResidualBlock(cost, new ceres::HuberLoss(config.epipolar_loss_scale * std::sqrt(n)), pose[a].data(),
                             pose[b].data());
    used.insert(a);
    used.insert(b);
  }
  bool prior_loss_used = false;
  for (const Prior& p : gauge.priors) {
    const int a = blockOf(p.a), b = blockOf(p.b);
    if (a == b) continue;
    const RelativePosePrior prior(p.rotation_ba, p.translation_ba, p.sigma_r, p.sigma_t);
    ceres::CostFunction* cost = nullptr;
    if (grouped)
      cost = new ceres::AutoDiffCostFunction<ThroughOffsets<RelativePosePrior>, 6, 7, 7>(
          new ThroughOffsets<RelativePosePrior>(prior, offsetOf(p.a), offsetOf(p.b)));
    else
      cost = new ceres::AutoDiffCostFunction<RelativePosePrior, 6, 7, 7>(new RelativePosePrior(prior));
    problem.AddResidualBlock(cost, prior_loss, pose[a].data(), pose[b].data());
    prior_loss_used = true;
    used.insert(a);
    used.insert(b);
  }
  if (!prior_loss_used) delete prior_loss;
  using PoseManifold = ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>;
  bool any_moving = false;
  for (int id : used) {
    problem.SetManifold(pose[id].data(), new PoseManifold);
    if (!gauge.moving.count(id))
      problem.SetParameterBlockConstant(pose[id].data());
    else
      any_moving = true;
  }
  if (!any_moving) return;
  ceres::Solver::Options options = solverOptions(config, deadline, config.epipolar_max_iterations);
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;  // no points to eliminate
  const std::string label = "epipolar adjustment " + where;
  const std::function<void(int)> on_iteration = [&](int iteration) {
    if (progress)
      progress->report(label, static_cast<size_t>(iteration), static_cast<size_t>(config.epipolar_max_iterations),
                       "iterations");
  };
  std::unique_ptr<IterationReporter> reporter;
  if (progress) {
    reporter = std::make_unique<IterationReporter>(on_iteration);
    options.callbacks.push_back(reporter.get());
  }
  BudgetGuard guard(deadline);
  options.callbacks.push_back(&guard);
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  if (progress) progress->end();
  if (config.verbose) std::fprintf(stderr, "%s\n", summary.FullReport().c_str());
  r.epipolar_iterations = static_cast<int>(summary.iterations.size());
  if (summary.termination_type == ceres::FAILURE || summary.termination_type == ceres::USER_FAILURE ||
      !std::isfinite(summary.final_cost) || summary.final_cost > summary.initial_cost) {
    s.poses = incoming;  // the rotations' start too
    r.rotations_adopted = false;
    r.epipolar_median_refined = r.epipolar_median_input;
    return;
  }
  for (const auto& [id, first] : leader)  // a moving run's images follow its leader's block
    if (used.count(first) && gauge.moving.count(first)) s.poses[id] = offset.at(id).applied(pose.at(first));
  takePoses(s, pose, used);
  r.epipolar_median_refined = medianSampson(s, pairs);
}

/// Stage `stage` of a pass begins with the points triangulated anew from the tracks, at the
/// poses as they are. Earlier triangulations admit more (the poses are still off), the last one
/// the final limit. Under a time budget a triangulation may take half of what is left; one that
/// cannot is given up, and the points stay as they were (the model's own, or the last
/// triangulation's): the first one given up still lets the adjustment run on the model's
/// points, a later one ends the pass (out_of_time).
void triangulationStage(PassResult& r, const Tracks& tracks, const std::set<int>& kept, const RefinementConfig& config,
                        int stage, const Deadline& deadline, const std::string& where, io::Progress* progress) {
  const int later = config.retriangulations - stage;
  if (!triangulationPaidFor(deadline, 1.0, observationsOf(tracks), config)) {  // as one given up, without the time spent on it
    r.not_begun.push_back("triangulation");
    r.out_of_time = stage > 0;
    return;
  }
  const PhaseTimer timer(r.seconds, "triangulation");
  if (retriangulate(r.state, tracks, kept, config,
                    config.triangulation_max_error * std::pow(config.triangulation_growth, std::max(0, later)),
                    deadline.half(), progress, "triangulating " + where))
    ++r.retriangulations;
  else
    r.out_of_time = stage > 0;
}

/// Rounds of adjust-then-filter of one stage, until a round filters (almost) nothing, the
/// rounds run out or the deadline passes (a round begun runs its solve at least briefly; none
/// begins after the deadline). Returns false when the adjustment failed or ran away (r.diverged, r.why).
bool adjustmentRounds(PassResult& r, const Gauge& gauge, const std::set<int>& kept, const RefinementConfig& config,
                      int stage, const Deadline& deadline, const std::string& where, io::Progress* progress) {
  State& s = r.state;
  const std::string label = "adjusting " + where;
  for (int round = 0; round < config.max_rounds; ++round) {
    const size_t before = s.observations();
    if (before == 0) break;
    // Not even a stage's first round once the time left cannot pay for Ceres' setup and one
    // iteration, less a tenth of the budget it may overrun by: at a 30-minute session's size
    // that alone is seconds past the budget.
    if (deadline.passed() || deadline.left() + 0.1 * config.max_seconds <
                                 kSolveSecondsPerObservation * static_cast<double>(before)) {
      r.out_of_time = true;
      if (!deadline.passed()) r.not_begun.push_back("adjustment");
      break;
    }
    const std::function<void(int)> on_iteration = [&](int iteration) {
      if (progress)
        progress->report(label, static_cast<size_t>(round), static_cast<size_t>(config.max_rounds), "rounds",
                         "iteration " + std::to_string(iteration));
    };
    ceres::Solver::Summary summary;
    {
      const PhaseTimer timer(r.seconds, "adjustment");
      summary = adjust(s, gauge, config, deadline, progress ? &on_iteration : nullptr);
    }
    ++r.rounds;
    r.iterations += static_cast<int>(summary.iterations.size());
    if (stage == 0 && round == 0) r.initial_cost = summary.initial_cost;
    r.final_cost = summary.final_cost;
    if (summary.termination_type == ceres::FAILURE || summary.termination_type == ceres::USER_FAILURE ||
        !std::isfinite(summary.final_cost) || summary.final_cost > summary.initial_cost * (1.0 + 1e-9)) {
      r.diverged = true;
      std::ostringstream why;
      why << "the adjustment failed in round " << r.rounds << " (" << summary.message << "; cost "
          << summary.initial_cost << " -> " << summary.final_cost << ")";
      r.why = why.str();
      return false;
    }
    if (summary.termination_type == ceres::NO_CONVERGENCE) r.converged = false;
    if (deadline.passed() || summary.termination_type == ceres::USER_SUCCESS) r.out_of_time = true;  // BudgetGuard
    const PhaseTimer timer(r.seconds, "filter");
    const auto [obs, pts] = filter(s, config, kept);
    r.observations_filtered += obs;
    r.points_filtered += pts;
    if (progress)
      progress->report(label, static_cast<size_t>(round + 1), static_cast<size_t>(config.max_rounds), "rounds");
    // A solve that leaves most observations far from their points has run away (points behind
    // the cameras, a degenerate minimum): that is not a correction of drift.
    if (static_cast<double>(obs) > config.max_filtered_ratio * static_cast<double>(before)) {
      r.diverged = true;
      std::ostringstream why;
      why << "the adjustment ran away in round " << r.rounds << ": " << obs << " of " << before
          << " observations left more than " << config.max_reprojection_error << " px from their points";
      r.why = why.str();
      return false;
    }
    if (static_cast<double>(obs) < 1e-3 * static_cast<double>(before)) break;
  }
  if (progress) progress->end();
  return true;
}

/// The pass's result aligned to the reference poses by a similarity (the movable images'
/// centres), when the caller held no image: the refined model stays in the SLAM frame.
void alignToReference(PassResult& r, const std::map<int, State::Pose>& reference, const std::set<int>& movable,
                      const std::set<int>& kept) {
  State& s = r.state;
  std::vector<int> ids;
  for (int id : movable)
    if (!kept.count(id) && s.poses.count(id)) ids.push_back(id);
  if (ids.size() < 3) return;
  Eigen::Matrix3Xd from(3, static_cast<long>(ids.size())), to(3, static_cast<long>(ids.size()));
  for (size_t q = 0; q < ids.size(); ++q) {
    from.col(static_cast<long>(q)) = s.poses.at(ids[q]).centre();
    to.col(static_cast<long>(q)) = reference.at(ids[q]).centre();
  }
  try {
    const eval::SimilarityTransform sim = eval::alignUmeyama(from, to);
    transform(s, sim);
    r.aligned = true;
    r.scale = sim.scale;
  } catch (const core::InvalidArgument&) {
    // collinear or coincident centres: the held first image defines the frame
  }
}

/// Stages of triangulation (with tracks) and adjust-then-filter rounds on `input`, with the
/// images in `kept` left out (their observations too) and those not in `movable` held; aligned
/// to the reference when the caller held nothing. `pass_number` names the pass in the progress.
PassResult pass(const State& input, const std::map<int, State::Pose>& reference,
                const std::set<int>& movable, const std::set<int>& kept,
                const RefinementConfig& config, const Tracks* tracks,
                const std::vector<EpipolarPair>* epipolar,
                const std::vector<PairRotation>* rotations, const Deadline& deadline,
                int pass_number = 1, io::Progress* progress = nullptr) {
  PassResult r;
  r.state = input;
  State& s = r.state;
  const bool caller_fixed = std::any_of(s.poses.begin(), s.poses.end(),
                                        [&](const auto& p) { return !movable.count(p.first); });
  // Before the first solve only what cannot take part goes (kept images, points behind a
  // camera): the input was triangulated at these poses, and what it left far from its points is
  // for the robust loss and the filter after the solve to judge.
  const auto [obs, pts] = filter(s, config, kept, false);
  r.observations_filtered += obs;
  r.points_filtered += pts;
  const Gauge gauge = gaugeOf(s, reference, movable, kept, config);
  const int stages = tracks ? 1 + config.retriangulations : 1;
  const std::map<int, State::Pose> before_epipolar = s.poses;
  if (tracks && config.triangulate_first && config.epipolar_first && epipolar && !epipolar->empty()) {
    if (triangulationPaidFor(deadline, 1.0 - config.epipolar_time_share, observationsOf(*tracks), config))
      epipolarStage(r, gauge, *epipolar, kept, config, deadline.share(config.epipolar_time_share),
                    "(pass " + std::to_string(pass_number) + ")", progress, rotations,
                    !caller_fixed);
    else
      r.not_begun.push_back("epipolar");
  }
  for (int stage = 0; stage < stages && !r.out_of_time; ++stage) {
    if (stage > 0 && deadline.passed()) {
      r.out_of_time = true;
      break;
    }
    const std::string where = stageName(pass_number, stage, stages);
    const int triangulated = r.retriangulations;
    if (stage > 0 || (tracks && config.triangulate_first))
      triangulationStage(r, *tracks, kept, config, stage, deadline, where, progress);
    if (stage == 0 && r.epipolar_iterations > 0 && r.retriangulations == triangulated) {
      // No time to triangulate at the poses the epipolar stage reached: the model's points were
      // made at the input poses, and adjusted against the moved ones they would all be outliers
      // (a 30-minute walk: 629,530 of 631,714 observations, "ran away"). The input poses it is.
      s.poses = before_epipolar;
      r.epipolar_undone = true;
    }
    if (r.out_of_time) break;
    if (!adjustmentRounds(r, gauge, kept, config, stage, deadline, where, progress)) return r;
  }
  if (!caller_fixed && config.align_to_input) alignToReference(r, reference, movable, kept);
  return r;
}

io::ColmapModel modelOf(const io::ColmapModel& input, const State& s) {
  io::ColmapModel out;
  out.cameras = input.cameras;
  out.images = input.images;
  for (auto& [id, im] : out.images) {
    im.rotation = s.poses.at(id).rotation;
    im.translation = s.poses.at(id).translation;
    for (auto& p : im.points2D) p.point3D_id = -1;
  }
  for (const auto& [id, track] : s.tracks) {
    io::ColmapPoint3D p;
    p.id = id;
    p.rgb = s.colours.count(id) ? s.colours.at(id) : std::array<uint8_t, 3>{{128, 128, 128}};
    p.xyz = s.points.at(id);
    p.track = track;
    double e = 0.0;
    for (const auto& o : track) {
      e += s.reproject(o.image_id, p.xyz, s.observed(o)).first;
      out.images.at(o.image_id).points2D[static_cast<size_t>(o.point2D_idx)].point3D_id = id;
    }
    p.error = track.empty() ? -1.0 : e / static_cast<double>(track.size());
    out.points[id] = std::move(p);
  }
  return out;
}

/// The movable images not kept yet whose correction in `s` is implausible (further than
/// max_correction_depth_ratio x their median depth, or turned more than max_correction_deg), or
/// that were left with too few observations (without priors), each with why.
std::map<int, std::string> implausibleCorrections(const State& s, const std::set<int>& movable,
                                                  const std::map<int, std::string>& kept,
                                                  const std::map<int, State::Pose>& reference,
                                                  const std::map<int, double>& depth, const RefinementConfig& config) {
  const bool priors = config.prior_translation_ratio > 0.0;
  // Drift grows with the distance travelled: a long session's correction is not implausible
  // because it is large (a 5-minute walk's odometry: 0.3 m and 12 degrees median, 20 at most).
  double path = 0.0;
  for (auto it = reference.begin(), next = std::next(it); it != reference.end() && next != reference.end(); ++it, ++next)
    path += (next->second.centre() - it->second.centre()).norm();
  const double max_turn = std::max(config.max_correction_deg, config.max_correction_deg_per_path * path);
  std::map<int, std::string> found;
  const std::map<int, int> observations = s.observationsPerImage();
  for (int id : movable) {
    if (kept.count(id)) continue;
    const double moved = (s.poses.at(id).centre() - reference.at(id).centre()).norm();
    const double turned = rotationBetweenDeg(s.poses.at(id).rotation, reference.at(id).rotation);
    std::ostringstream why;
    const double max_move = std::max(config.max_correction_depth_ratio * depth.at(id), config.max_correction_path_ratio * path);
    if (moved > max_move)
      why << "implausible correction: moved " << moved << " (more than " << config.max_correction_depth_ratio
          << " x its median depth " << depth.at(id) << " and " << config.max_correction_path_ratio
          << " x the path " << path << ")";
    else if (turned > max_turn)
      why << "implausible correction: turned " << turned << " deg (more than " << max_turn << ")";
    else if (!priors && observations.at(id) < config.min_observations)
      why << "too few observations after filtering (" << observations.at(id) << " < "
          << config.min_observations << ")";
    if (!why.str().empty()) found[id] = why.str();
  }
  return found;
}

/// The epipolar stage's figures, in every report of a pass.
void reportEpipolar(RefinementReport& rep, const PassResult& result) {
  rep.epipolar_correspondences = result.epipolar_correspondences;
  rep.epipolar_iterations = result.epipolar_iterations;
  rep.epipolar_median_input = result.epipolar_median_input;
  rep.epipolar_median_refined = result.epipolar_median_refined;
  rep.epipolar_undone = result.epipolar_undone;
  rep.rotation_pairs = result.rotation_pairs;
  rep.rotation_change_deg = result.rotation_change_deg;
  rep.rotations_adopted = result.rotations_adopted;
  for (const std::string& step : result.not_begun)
    if (std::find(rep.not_begun.begin(), rep.not_begun.end(), step) == rep.not_begun.end()) rep.not_begun.push_back(step);
}

/// The report of a refinement that diverged: every movable image keeps its input pose.
void reportDiverged(RefinementReport& rep, const PassResult& result) {
  rep.status = "diverged";
  rep.refined = false;
  rep.message = result.why + ": every keyframe keeps its input pose";
  for (auto& c : rep.images)
    if (c.movable) c.kept = "the adjustment diverged";
  rep.rounds = result.rounds;
  rep.iterations = result.iterations;
  rep.initial_cost = result.initial_cost;
  rep.final_cost = result.final_cost;
  reportEpipolar(rep, result);
}

/// The report of a refinement that ran: its figures, which images moved and which kept their
/// pose and why, and the sentence for the log.
void reportRefined(RefinementReport& rep, const PassResult& result, const std::map<int, std::string>& kept,
                   size_t movable, const RefinementConfig& config) {
  rep.status = result.out_of_time ? "out_of_time" : result.converged ? "converged" : "no_convergence";
  rep.refined = true;
  rep.rounds = result.rounds;
  rep.iterations = result.iterations;
  rep.initial_cost = result.initial_cost;
  rep.final_cost = result.final_cost;
  rep.observations_filtered = result.observations_filtered;
  rep.points_filtered = result.points_filtered;
  rep.aligned = result.aligned;
  rep.retriangulations = result.retriangulations;
  rep.alignment_scale = result.scale;
  reportEpipolar(rep, result);
  for (auto& c : rep.images) {
    if (!c.movable) continue;
    const auto k = kept.find(c.image_id);
    c.refined = k == kept.end();
    c.kept = c.refined ? "" : k->second;
  }
  std::ostringstream msg;
  const size_t moved = static_cast<size_t>(std::count_if(rep.images.begin(), rep.images.end(),
                                                         [](const ImageCorrection& c) { return c.refined; }));
  msg << "refined " << moved << " of " << movable << " movable images in " << rep.rounds << " rounds ("
      << rep.iterations << " iterations, " << rep.status << "); " << kept.size() << " kept their input pose";
  if (result.out_of_time) msg << "; stopped at its time budget of " << config.max_seconds << " s";
  if (result.epipolar_undone)
    msg << "; the epipolar stage's poses were undone (no time to triangulate at them)";
  rep.message = msg.str();
}

/// The report of a refinement whose budget was spent before anything was refined.
void reportUntouched(RefinementReport& rep, const PassResult& result, const RefinementConfig& config) {
  rep.status = "out_of_time";
  rep.refined = false;
  reportEpipolar(rep, result);
  for (auto& c : rep.images)
    if (c.movable) c.kept = "the time budget was spent before it was refined";
  std::ostringstream msg;
  if (result.rounds == 0 && result.epipolar_iterations == 0 && result.retriangulations == 0 && !rep.not_begun.empty()) {
    msg << "the time budget of " << config.max_seconds << " s would not pay for refining a model of this size (";
    for (size_t k = 0; k < rep.not_begun.size(); ++k) msg << (k ? ", " : "") << rep.not_begun[k];
    msg << " not begun): every image keeps its input pose";
  } else {
    msg << "the time budget of " << config.max_seconds
        << " s was spent before an adjustment began: every image keeps its input pose";
    if (result.epipolar_undone) msg << " (the epipolar stage's poses were undone)";
  }
  rep.message = msg.str();
}

/// config.epipolar_only: the epipolar stage on the whole budget, the result aligned to the
/// reference when every image moved, an implausible correction put back (as a refinement's second
/// pass would keep it), the points left out. The model as it came (nullopt) when the stage moved
/// nothing.
/// `s` comes as the input and leaves as the result.
std::optional<io::ColmapModel> epipolarOnly(RefinementReport& rep, const io::ColmapModel& input,
                                            State& s, const std::map<int, State::Pose>& reference,
                                            const std::set<int>& movable,
                                            const std::map<int, double>& depth,
                                            const std::vector<EpipolarPair>& epipolar,
                                            const std::vector<PairRotation>* rotations,
                                            const RefinementConfig& config,
                                            const Deadline& deadline, io::Progress* progress) {
  PassResult r;
  r.state = s;
  const Gauge gauge = gaugeOf(r.state, reference, movable, {}, config);
  {
    State at_reference = s;
    std::vector<const EpipolarPair*> pairs;
    for (const auto& [id, pose] : reference)
      if (at_reference.poses.count(id)) at_reference.poses[id] = pose;
    for (const auto& p : epipolar)
      if (at_reference.poses.count(p.a) && at_reference.poses.count(p.b)) pairs.push_back(&p);
    rep.epipolar_median_reference = medianSampson(at_reference, pairs);
  }
  epipolarStage(r, gauge, epipolar, {}, config, deadline, "(epipolar only)", progress, rotations,
                movable.size() == s.poses.size());
  for (const auto& [name, seconds] : r.seconds) rep.phase_seconds[name] += seconds;
  if (r.epipolar_iterations == 0 || r.epipolar_median_refined == r.epipolar_median_input) {
    reportEpipolar(rep, r);
    rep.status = "nothing_to_refine";
    rep.message = "the epipolar stage moved nothing: every image keeps its input pose";
    for (auto& c : rep.images)
      if (c.movable) c.kept = "the epipolar stage moved nothing";
    return std::nullopt;
  }
  if (movable.size() == s.poses.size() && config.align_to_input) alignToReference(r, reference, movable, {});
  const std::map<int, std::string> kept = implausibleCorrections(r.state, movable, {}, reference, depth, config);
  for (const auto& [id, why] : kept) r.state.poses[id] = reference.at(id);
  r.out_of_time = deadline.passed();
  reportRefined(rep, r, kept, movable.size(), config);
  rep.status = "epipolar_only";
  std::ostringstream msg;
  msg << "the epipolar stage moved " << (movable.size() - kept.size()) << " of " << movable.size() << " images in "
      << r.epipolar_iterations << " iterations (median Sampson distance " << r.epipolar_median_input << " -> "
      << r.epipolar_median_refined << " px); " << kept.size() << " kept their input pose; no points";
  rep.message = msg.str();
  s = std::move(r.state);
  s.tracks.clear();
  s.points.clear();
  s.colours.clear();
  return modelOf(input, s);
}

}  // namespace

void RefinementConfig::validate() const {
  if (loss != "cauchy" && loss != "huber" && loss != "soft_l1" && loss != "trivial")
    throw core::InvalidArgument("loss must be cauchy, huber, soft_l1 or trivial, not '" + loss + "'");
  if (!(loss_scale > 0.0)) throw core::InvalidArgument("loss_scale must be positive [px]");
  if (!(max_reprojection_error > 0.0)) throw core::InvalidArgument("max_reprojection_error must be positive [px]");
  if (!(min_triangulation_angle_deg >= 0.0 && min_triangulation_angle_deg < 90.0))
    throw core::InvalidArgument("min_triangulation_angle_deg must be in [0, 90)");
  if (max_rounds < 1 || max_iterations < 1) throw core::InvalidArgument("max_rounds and max_iterations must be >= 1");
  if (!(function_tolerance > 0.0 && function_tolerance < 1.0))
    throw core::InvalidArgument("function_tolerance must be in (0, 1)");
  if (min_observations < 0) throw core::InvalidArgument("min_observations must be >= 0");
  if (!(max_correction_depth_ratio > 0.0)) throw core::InvalidArgument("max_correction_depth_ratio must be positive");
  if (!(rotation_pair_sigma_deg > 0.0) || !(rotation_min_change_deg >= 0.0) ||
      rotation_iterations < 1)
    throw core::InvalidArgument(
        "rotation_pair_sigma_deg must be positive, rotation_min_change_deg >= 0, "
        "rotation_iterations >= 1");
  if (!(max_correction_deg > 0.0 && max_correction_deg <= 180.0))
    throw core::InvalidArgument("max_correction_deg must be in (0, 180]");
  if (threads < 0) throw core::InvalidArgument("threads must be >= 0");
  if (!(triangulation_max_error > 0.0)) throw core::InvalidArgument("triangulation_max_error must be positive [px]");
  if (retriangulations < 0) throw core::InvalidArgument("retriangulations must be >= 0");
  if (!(max_seconds >= 0.0)) throw core::InvalidArgument("max_seconds must be >= 0 (0: no limit)");
  if (!(max_filtered_ratio > 0.0 && max_filtered_ratio <= 1.0))
    throw core::InvalidArgument("max_filtered_ratio must be in (0, 1]");
  if (!(prior_translation_ratio >= 0.0)) throw core::InvalidArgument("prior_translation_ratio must be >= 0");
  if (!(prior_rotation_deg > 0.0)) throw core::InvalidArgument("prior_rotation_deg must be positive");
  if (!(prior_loss_scale > 0.0)) throw core::InvalidArgument("prior_loss_scale must be positive");
  if (!(max_correction_path_ratio >= 0.0)) throw core::InvalidArgument("max_correction_path_ratio must be >= 0");
  if (!(max_correction_deg_per_path >= 0.0)) throw core::InvalidArgument("max_correction_deg_per_path must be >= 0");
  if (epipolar_max_iterations < 1) throw core::InvalidArgument("epipolar_max_iterations must be >= 1");
  if (epipolar_matches_per_pair < 1) throw core::InvalidArgument("epipolar_matches_per_pair must be >= 1");
  if (!(epipolar_loss_scale > 0.0)) throw core::InvalidArgument("epipolar_loss_scale must be positive [px]");
  if (!(epipolar_time_share > 0.0 && epipolar_time_share <= 1.0))
    throw core::InvalidArgument("epipolar_time_share must be in (0, 1]");
  if (!(triangulation_seconds_per_observation >= 0.0))
    throw core::InvalidArgument("triangulation_seconds_per_observation must be >= 0");
}

std::set<int> allImages(const io::ColmapModel& model) {
  std::set<int> ids;
  for (const auto& [id, im] : model.images) ids.insert(id);
  return ids;
}

namespace {

/// The mean reprojection error [px] of a point over its track in `model`; -1 (COLMAP's unknown)
/// when a camera of its track is not a pinhole one or the point is not in front of it.
double meanReprojectionError(const io::ColmapModel& model, const io::ColmapPoint3D& p) {
  double sum = 0.0;
  for (const io::ColmapTrackElement& e : p.track) {
    const io::ColmapImage& im = model.images.at(e.image_id);
    const io::ColmapCamera& camera = model.cameras.at(im.camera_id);
    if (!isPinhole(camera)) return -1.0;
    const Eigen::Vector4d k = pinhole(camera);
    const Eigen::Vector3d x = im.rotation * p.xyz + im.translation;
    if (!(x.z() > 0.0) || static_cast<size_t>(e.point2D_idx) >= im.points2D.size()) return -1.0;
    const Eigen::Vector2d px(k[0] * x.x() / x.z() + k[2], k[1] * x.y() / x.z() + k[3]);
    sum += (px - im.points2D[static_cast<size_t>(e.point2D_idx)].xy).norm();
  }
  return p.track.empty() ? -1.0 : sum / static_cast<double>(p.track.size());
}

}  // namespace

io::ColmapModel startedAt(const io::ColmapModel& model, const io::ColmapModel& start) {
  io::ColmapModel out = model;
  std::map<int, std::pair<Eigen::Quaterniond, Eigen::Vector3d>> before;
  for (auto& [id, im] : out.images) {
    const auto it = start.images.find(id);
    if (it == start.images.end()) continue;
    if (!it->second.rotation.coeffs().allFinite() || !it->second.translation.allFinite())
      throw core::InvalidArgument("start image " + it->second.name + " has a non-finite pose");
    before[id] = {im.rotation, im.translation};
    im.rotation = it->second.rotation.normalized();
    im.translation = it->second.translation;
  }
  for (auto& [pid, p] : out.points) {
    if (p.track.empty()) continue;
    const auto moved = before.find(p.track.front().image_id);
    if (moved != before.end()) {
      const io::ColmapImage& now = out.images.at(moved->first);
      const Eigen::Vector3d in_camera = moved->second.first * p.xyz + moved->second.second;
      p.xyz = now.rotation.conjugate() * (in_camera - now.translation);
    }
    // Its error is of the poses it was triangulated at: measured again where one of its images
    // moved (the model may be written as it is, out of time, and COLMAP reads the error).
    if (std::any_of(p.track.begin(), p.track.end(),
                    [&](const io::ColmapTrackElement& e) { return before.count(e.image_id) > 0; }))
      p.error = meanReprojectionError(out, p);
  }
  return out;
}

io::ColmapModel refineModel(const io::ColmapModel& input, const std::set<int>& movable,
                            const RefinementConfig& config, RefinementReport* report,
                            const io::ColmapModel* reference_model,
                            const std::vector<Match>* matches, io::Progress* progress,
                            const std::vector<PairRotation>* rotations) {
  std::optional<io::ColmapModel> refined = refineModelIfChanged(
      input, movable, config, report, reference_model, matches, progress, rotations);
  return refined ? std::move(*refined) : input;
}

std::optional<io::ColmapModel> refineModelIfChanged(
    const io::ColmapModel& input, const std::set<int>& movable_in, const RefinementConfig& config,
    RefinementReport* report, const io::ColmapModel* reference_model,
    const std::vector<Match>* matches, io::Progress* progress,
    const std::vector<PairRotation>* rotations) {
  const auto start = std::chrono::steady_clock::now();
  config.validate();
  Deadline deadline;
  if (config.max_seconds > 0.0) {
    deadline.set = true;
    const Clock::time_point from = config.budget_start == Clock::time_point{} ? start : config.budget_start;
    deadline.at = from + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(config.max_seconds));
  }
  RefinementReport local;
  RefinementReport& rep = report ? *report : local;
  rep = RefinementReport{};
  std::optional<PhaseTimer> setup_timer(std::in_place, rep.phase_seconds, "setup");
  const State initial = stateOf(input);
  // The poses corrections are measured against (and the result aligned to): the reference's
  // where it has the image, else the input's.
  std::map<int, State::Pose> reference = initial.poses;
  if (reference_model)
    for (const auto& [id, im] : reference_model->images)
      if (reference.count(id)) {
        if (!im.rotation.coeffs().allFinite() || !im.translation.allFinite())
          throw core::InvalidArgument("reference image " + im.name + " has a non-finite pose");
        reference[id] = {im.rotation.normalized(), im.translation};
      }
  std::set<int> movable;
  for (int id : movable_in)
    if (initial.poses.count(id)) movable.insert(id);
  // A budget spent before this (refine_model reads the model and the matches within it): nothing
  // more is done, not even the tracks (a second at a 30-minute session's size).
  const bool spent = deadline.passed();
  // Matches whose triangulation the time left would not pay for even now, before their tracks
  // and epipolar pairs are built (by the observations the matches hold: at most the tracks').
  // A 30-minute session's finish: 2.1 million observations at 1 us against 3.7 s left after
  // reading, where building them took 2.4-3.8 s to end in nothing.
  const bool unpaid = matches && !spent && !config.epipolar_only && config.triangulate_first && deadline.set &&
                      !triangulationPaidFor(deadline, 1.0, countObservations(*matches), config);
  Tracks tracks;
  if (config.epipolar_only && (!matches || !(config.prior_translation_ratio > 0.0) || !config.epipolar_first))
    throw core::InvalidArgument("epipolar_only needs the matches, the priors and epipolar_first");
  if (matches && !spent && !unpaid && !config.epipolar_only) tracks = buildTracks(*matches);
  std::vector<EpipolarPair> epipolar;
  if (matches && config.epipolar_first && !spent && !unpaid) {
    // The images by id in a table where the ids are small (the database's: 1, 2, ...): two
    // lookups a match, 7 million at 30 minutes, were a map's.
    const int max_id = initial.images.empty() ? 0 : initial.images.rbegin()->first;
    const bool dense = !initial.images.empty() && initial.images.begin()->first >= 0 && max_id < (1 << 24);
    std::vector<const io::ColmapImage*> by_id(dense ? static_cast<size_t>(max_id) + 1 : 0, nullptr);
    if (dense)
      for (const auto& [id, im] : initial.images) by_id[static_cast<size_t>(id)] = im;
    const auto imageOf = [&](int id) -> const io::ColmapImage* {
      if (dense) return id >= 0 && id <= max_id ? by_id[static_cast<size_t>(id)] : nullptr;
      const auto it = initial.images.find(id);
      return it == initial.images.end() ? nullptr : it->second;
    };
    epipolar = epipolarPairs(
        *matches, config.epipolar_matches_per_pair, config.epipolar_min_matches,
        [&](int id) { return imageOf(id) != nullptr; },
        [&](int id, int index) -> Eigen::Vector2d {
          const auto& points = imageOf(id)->points2D;
          return index >= 0 && static_cast<size_t>(index) < points.size() ? points[static_cast<size_t>(index)].xy
                                                                           : Eigen::Vector2d(NAN, NAN);
        },
        [&](int id) { return initial.intrinsics.at(id); });
  }
  const Tracks* with_tracks = matches && !unpaid ? &tracks : nullptr;
  rep.tracks = tracks.tracks.size();
  rep.track_conflicts = tracks.conflicts;
  rep.points_input = initial.points.size();
  rep.observations_input = initial.observations();
  rep.reprojection_error_input = initial.meanError();

  const std::map<int, int> observations_input = initial.observationsPerImage();
  const std::map<int, double> depth = medianDepths(initial);
  setup_timer.reset();
  // The report's figures of the result: a model returned as it came (nullopt: no copy of it,
  // and its figures are the input's, not computed again: 0.5 s at a 30-minute session's size).
  const auto finish = [&](std::optional<io::ColmapModel> model, const State& s) {
    rep.unchanged = !model;
    rep.points_refined = s.points.size();
    rep.observations_refined = rep.unchanged ? rep.observations_input : s.observations();
    rep.reprojection_error_refined = rep.unchanged ? rep.reprojection_error_input : s.meanError();
    const std::map<int, int> observations = rep.unchanged ? observations_input : s.observationsPerImage();
    for (auto& c : rep.images) {
      c.observations_refined = observations.count(c.image_id) ? observations.at(c.image_id) : 0;
      c.weak = c.refined && c.observations_refined < config.min_observations;
      c.centre_refined = s.poses.at(c.image_id).centre();
      c.translation = (c.centre_refined - c.centre_input).norm();
      c.rotation_deg = rotationBetweenDeg(s.poses.at(c.image_id).rotation, reference.at(c.image_id).rotation);
    }
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return model;
  };
  for (const auto& [id, pose] : initial.poses) {
    ImageCorrection c;
    c.image_id = id;
    c.name = initial.images.at(id)->name;
    c.movable = movable.count(id) > 0;
    c.centre_input = reference.at(id).centre();
    c.observations_input = observations_input.at(id);
    c.median_depth = depth.at(id);
    rep.images.push_back(c);
  }
  if (spent) {
    rep.status = "out_of_time";
    std::ostringstream msg;
    msg << "the time budget of " << config.max_seconds
        << " s was spent before the refinement began (reading the model and the matches): the model as it came";
    rep.message = msg.str();
    for (auto& c : rep.images)
      if (c.movable) c.kept = "the time budget was spent before it was refined";
    return finish(std::nullopt, initial);
  }
  if (config.epipolar_only) {
    State s = initial;
    std::optional<io::ColmapModel> model = epipolarOnly(
        rep, input, s, reference, movable, depth, epipolar, rotations, config, deadline, progress);
    if (progress) progress->end();
    return finish(std::move(model), s);
  }
  if (movable.empty() && with_tracks) {
    // Nothing may move: the matches are triangulated at the given poses, nothing adjusted (what
    // the model's points would be at these poses with these matches).
    State s = initial;
    if (!retriangulate(s, tracks, {}, config, config.triangulation_max_error, deadline, progress,
                       "triangulating at the given poses")) {
      std::ostringstream msg;
      msg << "no image may move, and the time budget of " << config.max_seconds
          << " s was spent before the matches were triangulated: the model as it came";
      rep.status = "out_of_time";
      rep.message = msg.str();
      return finish(std::nullopt, initial);
    }
    filter(s, config, {});
    rep.status = "triangulated";
    rep.retriangulations = 1;
    rep.message = "no image may move: the matches triangulated at the given poses";
    return finish(modelOf(input, s), s);
  }
  if (unpaid && !movable.empty()) {
    // Without the triangulation only an adjustment of the model's own points from the input
    // poses is left. It begins only when the time left pays for its setup and ten iterations:
    // one or two of them on a long session (1,000-5,600 keyframes) moved nothing that counts
    // (0.99x of a 5-minute walk's drift) and made the finish seconds longer.
    if (config.epipolar_first) rep.not_begun.push_back("epipolar");
    rep.not_begun.push_back("triangulation");
    if (deadline.left() < kAdjustmentAloneSolves * kSolveSecondsPerObservation *
                              static_cast<double>(initial.observations())) {
      rep.not_begun.push_back("adjustment");
      reportUntouched(rep, PassResult{}, config);
      return finish(std::nullopt, initial);
    }
  }
  if (movable.empty() || initial.observations() == 0) {
    rep.status = "nothing_to_refine";
    rep.message = movable.empty() ? "no image may move" : "the model has no observations";
    return finish(std::nullopt, initial);
  }

  // Images too weakly held to be refined keep their input poses from the start.
  std::map<int, std::string> kept;
  const bool priors = config.prior_translation_ratio > 0.0;
  for (int id : movable)
    if (!priors && observations_input.at(id) < config.min_observations)
      kept[id] = "too few observations (" + std::to_string(observations_input.at(id)) + " < " +
                 std::to_string(config.min_observations) + ")";

  const auto keptIds = [&]() {
    std::set<int> ids;
    for (const auto& [id, why] : kept) ids.insert(id);
    return ids;
  };
  const auto addSeconds = [&](const PassResult& r) {
    for (const auto& [name, seconds] : r.seconds) rep.phase_seconds[name] += seconds;
  };
  PassResult result = pass(initial, reference, movable, keptIds(), config, with_tracks, &epipolar,
                           rotations, deadline, 1, progress);
  addSeconds(result);
  // Implausible corrections, or images left without enough observations: start again with them
  // kept at their input poses (once; what the second pass still moves too far is put back).
  if (!result.diverged) {
    const std::map<int, std::string> offenders =
        implausibleCorrections(result.state, movable, kept, reference, depth, config);
    kept.insert(offenders.begin(), offenders.end());
    if (!offenders.empty() && !deadline.passed()) {
      rep.passes = 2;
      result = pass(initial, reference, movable, keptIds(), config, with_tracks, &epipolar,
                    rotations, deadline, 2, progress);
      addSeconds(result);
    }
  }
  if (progress) progress->end();
  if (result.diverged) {
    reportDiverged(rep, result);
    return finish(std::nullopt, initial);
  }
  if (result.rounds == 0 && (result.retriangulations == 0 || result.epipolar_iterations == 0)) {
    // The budget was spent before an adjustment began, and no epipolar stage's poses were
    // triangulated at: points triangulated anew at the input poses are not a refinement; the
    // model as it came. (The epipolar stage's poses with their points are kept: on a 10-minute
    // walk they are most of the correction, 526 -> 152 mm; on a small arc with little drift
    // they can be worse than the input, 6.5 -> 14.9 mm, where the adjustment after them brings
    // 1.3 mm. Dropping them at the moment the budget ran out would make the result jump between
    // the two with the machine's speed.)
    reportUntouched(rep, result, config);
    return finish(std::nullopt, initial);
  }
  State& s = result.state;
  if (rep.passes == 2)
    for (const auto& [id, why] : implausibleCorrections(s, movable, kept, reference, depth, config))
      kept[id] = why + " (second pass)";
  // Kept images sit at their input poses; their observations that fit the refined points stay.
  std::set<int> none;
  for (const auto& [id, why] : kept) s.poses[id] = reference.at(id);
  // Kept images at their input poses take part again: the tracks triangulated once more, within
  // what is left of the budget. Out of time, the points stay the pass's; when those are the
  // input's own (no triangulation ran), the kept images' input observations join them below.
  std::optional<PhaseTimer> kept_timer(std::in_place, rep.phase_seconds, "triangulation");
  const bool kept_triangulated = !kept.empty() && with_tracks &&
                                 retriangulate(s, tracks, {}, config, config.triangulation_max_error, deadline,
                                               progress, "triangulating with the kept images");
  kept_timer.reset();
  if (!kept.empty() && with_tracks && !kept_triangulated) result.out_of_time = true;
  if (kept_triangulated) {
    ++result.retriangulations;
    const auto [obs, pts] = filter(s, config, none);
    result.observations_filtered += obs;
    result.points_filtered += pts;
  } else if (!kept.empty() && with_tracks && result.retriangulations > 0) {
    const auto [obs, pts] = filter(s, config, none);  // points of the matches: the kept images see none
    result.observations_filtered += obs;
    result.points_filtered += pts;
  } else if (!kept.empty()) {
    State with_kept = s;
    for (const auto& [pid, x] : initial.points)
      if (with_kept.points.count(pid)) {
        auto& track = with_kept.tracks[pid];
        for (const auto& e : initial.tracks.at(pid))
          if (kept.count(e.image_id) &&
              std::none_of(track.begin(), track.end(), [&](const io::ColmapTrackElement& t) {
                return t.image_id == e.image_id && t.point2D_idx == e.point2D_idx;
              }))
            track.push_back(e);
      }
    const auto [obs, pts] = filter(with_kept, config, none);
    result.observations_filtered += obs;
    result.points_filtered += pts;
    s = std::move(with_kept);
  }
  reportRefined(rep, result, kept, movable.size(), config);
  return finish(modelOf(input, s), s);
}

}  // namespace view_selection::refine
