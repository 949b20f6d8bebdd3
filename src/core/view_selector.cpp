#include "view_selection/core/view_selector.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/pose_interpolation.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

namespace view_selection::core {

namespace {
double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}
}  // namespace

namespace {
/// The parameters as they act: the gate's preset applied (params() reports these).
ViewSelectorConfig inForce(ViewSelectorConfig config) {
  config.matrix.applyGate();
  return config;
}
}  // namespace

void ViewSelectorConfig::visitParameters(ParameterVisitor& v) {
  keyframes.visitParameters(v);
  matrix.visitParameters(v);
  selection.visitParameters(v);
}

ViewSelector::ViewSelector(ViewSelectorConfig config, std::unique_ptr<PointSource> points)
    : config_(inForce(std::move(config))),
      points_(std::move(points)),
      policy_(config_.keyframes),
      matrix_(config_.matrix) {
  config_.validate();
  if (!points_) throw InvalidArgument("ViewSelector needs a point source");
}

FrameResult ViewSelector::addFrame(const Frame& frame) {
  validateFrame(frame);
  if (last_stamp_ && !(frame.stamp > *last_stamp_)) {
    std::ostringstream s;
    s.precision(17);
    s << "frame stamp " << frame.stamp << " is not after the previous frame's " << *last_stamp_
      << (frame.stamp == *last_stamp_ ? " (duplicate)" : " (out of order)");
    throw InvalidInput(s.str());
  }
  CameraPose pose = frame.pose;
  pose.orientation.normalize();
  // Transactional: a frame that fails anywhere (e.g. the point source finds no depth) leaves
  // the policy, the last stamp and the matrix exactly as they were.
  const KeyframePolicy policy_before = policy_;
  try {
    FrameResult result = insert(frame, pose);
    last_stamp_ = frame.stamp;
    return result;
  } catch (...) {
    policy_ = policy_before;
    throw;
  }
}

const KeyframeReference* ViewSelector::keyframeReference() const {
  const size_t n = matrix_.size();
  if (n == 0) return nullptr;
  const Keyframe& last = matrix_.keyframe(static_cast<ViewId>(n - 1));
  KeyframeReference& r = reference_;
  r.pose = last.pose;
  r.intrinsics = last.intrinsics;
  r.max_parallax_deg = kOverlapMaxParallaxDeg;  // fixed: the gate's tuning moves no keyframe
  r.max_scale_ratio = kOverlapMaxScaleRatio;
  r.points = &last.points;
  r.stamp = last.stamp;
  if (last.points.cols() >= kMinReferencePoints) return &r;
  // No points to compare with (a feature keyframe that triangulated nothing yet, a map not
  // there yet): a plane across the last keyframe's image at the scene depth of the latest
  // keyframe before it that has points, so the rule keeps its scale. None: no reference.
  const long stop = std::max<long>(0, static_cast<long>(n) - 1 - kReferenceLookBack);
  for (long j = static_cast<long>(n) - 2; j >= stop; --j) {
    const Keyframe& k = matrix_.keyframe(static_cast<ViewId>(j));
    if (k.points.cols() < kMinReferencePoints) continue;
    const Eigen::Matrix3d world_to_camera = k.pose.rotation().transpose();
    std::vector<double> depths;
    for (Eigen::Index q = 0; q < k.points.cols(); ++q) {
      const double z = (world_to_camera * (k.points.col(q) - k.pose.position)).z();
      if (z > 0.0) depths.push_back(z);
    }
    if (depths.size() < static_cast<size_t>(kMinReferencePoints)) continue;
    std::nth_element(depths.begin(), depths.begin() + static_cast<std::ptrdiff_t>(depths.size() / 2),
                     depths.end());
    const double depth = depths[depths.size() / 2];
    constexpr int kCols = 8, kRows = 6;
    r.plane.resize(3, kCols * kRows);
    const Eigen::Matrix3d rotation = last.pose.rotation();
    const PinholeIntrinsics& in = last.intrinsics;
    for (int y = 0; y < kRows; ++y)
      for (int x = 0; x < kCols; ++x) {
        const Eigen::Vector2d pixel((x + 0.5) * in.width / kCols, (y + 0.5) * in.height / kRows);
        r.plane.col(y * kCols + x) = last.pose.position + rotation * (in.backProject(pixel) * depth);
      }
    r.points = &r.plane;
    return &r;
  }
  r.points = nullptr;  // no keyframe has points: the policy's start-up rule (kNoPointsInterval)
  return &r;
}

bool ViewSelector::revisitRuleApplies(const KeyframePolicy& policy) const {
  // Only where the policy measured the view against the last keyframe's points: not at the
  // start (no keyframe has points yet), not for the other modes (a photo collection keeps every
  // photo, the SLAM's keyframes are its own).
  return policy.config().mode == KeyframeMode::kScaleFree && policy.lastChange().has_value() &&
         matrix_.size() > 1;
}

ViewId ViewSelector::coveringKeyframe(const CameraPose& pose,
                                      const PinholeIntrinsics& intrinsics) const {
  const ViewId last = static_cast<ViewId>(matrix_.size()) - 1;
  neighbours_.query(pose, std::sqrt(intrinsics.fx * intrinsics.fy), kOverlapMaxScaleRatio,
                    kRevisitCandidates, near_);
  for (const ViewId id : near_) {
    if (id == last) continue;  // measured already: it does not have the view
    if (keyframeCovers(id, pose, intrinsics)) return id;
  }
  return -1;
}

bool ViewSelector::keyframeCovers(ViewId id, const CameraPose& pose,
                                  const PinholeIntrinsics& intrinsics) const {
  const Keyframe& k = matrix_.keyframe(id);
  KeyframeReference r;
  r.max_parallax_deg = kOverlapMaxParallaxDeg;  // the last keyframe's gate: fixed
  r.max_scale_ratio = kOverlapMaxScaleRatio;
  r.pose = k.pose;
  r.intrinsics = k.intrinsics;
  r.points = &k.points;
  r.stamp = k.stamp;
  return policy_.covers(r, pose, intrinsics);
}

bool ViewSelector::registers() const {
  return registration_ && config_.keyframes.revisit_registration &&
         config_.keyframes.mode == KeyframeMode::kScaleFree;
}

ViewId ViewSelector::registeredCoveringKeyframe(const Frame& frame, const CameraPose& pose) {
  if (!registers()) return -1;
  // Keyframes below this id may be asked: those made kRecentSeconds or more before the frame
  // (the stamps grow with the ids).
  ViewId older = static_cast<ViewId>(matrix_.size());
  while (older > 0 && matrix_.keyframe(older - 1).stamp > frame.stamp - kRecentSeconds) --older;
  if (older <= 0) return -1;
  const double focal = std::sqrt(frame.intrinsics.fx * frame.intrinsics.fy);
  // The candidates, each list the kRegisteredCandidates most alike: by pose where the last
  // registration placed the frame before it (consecutive frames share their drift against an
  // earlier pass), by the images (which drift does not move), by pose where the frame's own pose
  // places it.
  std::vector<ViewId> candidates;
  if (revisit_offset_) {
    neighbours_.query(composePoses(*revisit_offset_, pose), focal, kOverlapMaxScaleRatio,
                      kRegisteredCandidates, near_, older);
    candidates = near_;
  }
  neighbours_.query(pose, focal, kOverlapMaxScaleRatio, kRegisteredCandidates, near_, older);
  std::vector<ViewId> alike = registration_->alikeKeyframes(frame, older, kRegisteredCandidates);
  for (const std::vector<ViewId>* list : {&alike, &near_})
    for (const ViewId id : *list)
      if (std::find(candidates.begin(), candidates.end(), id) == candidates.end())
        candidates.push_back(id);
  for (const ViewId id : candidates) {
    const std::optional<CameraPose> relative = registration_->relativePose(frame, id);
    if (!relative || !relative->isValid()) continue;
    // Where the images put the frame in that keyframe's world: its pose composed with the
    // frame's pose relative to it; and the offset from the frame's pose to there (world to
    // world), for the next frames' candidates.
    const CameraPose registered = composePoses(matrix_.keyframe(id).pose, *relative);
    revisit_offset_ = composePoses(registered, inversePose(pose));
    // The keyframes made just before and after it share its drift: the frame is measured
    // against them at the registered pose, nearest in id first (the keyframe itself first),
    // among those that may be asked.
    const auto covers = [&](ViewId c) {
      return c >= 0 && c < older && keyframeCovers(c, registered, frame.intrinsics);
    };
    if (covers(id)) return id;
    for (ViewId step = 1; step <= kRegisteredWindow; ++step) {
      if (covers(id - step)) return id - step;
      if (covers(id + step)) return id + step;
    }
  }
  return -1;
}

void ViewSelector::setRegistration(std::unique_ptr<FrameRegistration> registration) {
  registration_ = std::move(registration);
}

void ViewSelector::indexNeighbours() {
  neighbours_.clear();
  for (size_t i = 0; i < matrix_.size(); ++i)
    neighbours_.update(static_cast<ViewId>(i), matrix_.keyframe(static_cast<ViewId>(i)),
                       config_.keyframes.keyframe_overlap);
}

FrameResult ViewSelector::insert(const Frame& frame, const CameraPose& pose) {
  FrameResult result;
  const KeyframeReference* reference = policy_.needsReference() ? keyframeReference() : nullptr;
  const bool take =
      policy_.offer(pose, frame.external_keyframe, reference, &frame.intrinsics, frame.stamp);
  if (!take) return result;
  if (revisitRuleApplies(policy_)) {
    result.covered_by = coveringKeyframe(pose, frame.intrinsics);
    if (result.covered_by < 0) {
      result.covered_by = registeredCoveringKeyframe(frame, pose);
      result.covered_by_registration = result.covered_by >= 0;
      if (result.covered_by_registration) ++revisits_registered_;
    }
    // A keyframe made right after frames recognised from their images is where the walk leaves
    // a revisit the poses do not show: it is linked to the keyframe that covered the last one.
    if (result.covered_by >= 0) {
      revisit_link_ = result.covered_by_registration ? result.covered_by : -1;
      ++revisits_skipped_;
      return result;
    }
  }

  const auto t_points = std::chrono::steady_clock::now();
  const ViewId id = static_cast<ViewId>(matrix_.size());
  // The point source sees the same normalised pose as the matrix, so a caller's quaternion of
  // norm 1 +- rounding gives bit-identical points whichever path (node, tool) normalised it.
  Frame normalised = frame;  // the images are views: pixels are shared, not copied
  normalised.pose = pose;
  PointSourceResult points = points_->process(id, normalised);
  if (!points.points.allFinite()) throw InvalidInput("point source produced non-finite points");
  for (const auto& [view, updated] : points.updated) {
    if (view < 0 || view >= id || !updated.allFinite())
      throw InvalidInput("point source produced an invalid update for view " +
                         std::to_string(view));
  }
  result.points_seconds = secondsSince(t_points);

  Keyframe keyframe;
  keyframe.stamp = frame.stamp;
  keyframe.image_name = frame.image_name;
  keyframe.intrinsics = frame.intrinsics;
  keyframe.pose = pose;
  keyframe.points = std::move(points.points);
  keyframe.revisit_of = revisit_link_;
  revisit_link_ = -1;
  const OcclusionConfig& occlusion = config_.matrix.occlusion;
  if (occlusion.enabled && !frame.depth.empty())
    keyframe.depth = std::make_shared<const DepthMap>(
        makeOcclusionMap(frame.depth, frame.intrinsics, occlusion.depth_map_cell));
  result.points = static_cast<size_t>(keyframe.points.cols());

  // Nothing below throws for inputs validated above: the matrix is never left half-updated.
  const auto t_matrix = std::chrono::steady_clock::now();
  result.id = matrix_.addKeyframe(std::move(keyframe));
  const double overlap = config_.keyframes.keyframe_overlap;
  neighbours_.update(result.id, matrix_.keyframe(result.id), overlap);
  for (auto& [view, updated] : points.updated) {
    matrix_.setPoints(view, std::move(updated));
    neighbours_.update(view, matrix_.keyframe(view), overlap);
    result.updated_rows.push_back(view);
  }
  result.matrix_seconds = secondsSince(t_matrix);
  policy_.keyframeAccepted(pose);
  // Only the revisit rule registers frames: a policy without it keeps nothing for it.
  if (registers()) registration_->keyframeAdded(result.id, normalised);
  result.outcome = FrameOutcome::kKeyframe;
  return result;
}

bool ViewSelector::wantsFrame(const Frame& frame) const {
  KeyframePolicy probe = policy_;
  CameraPose pose = frame.pose;
  pose.orientation.normalize();  // as addFrame does
  const KeyframeReference* reference = probe.needsReference() ? keyframeReference() : nullptr;
  if (!probe.offer(pose, frame.external_keyframe, reference, &frame.intrinsics, frame.stamp))
    return false;
  return !revisitRuleApplies(probe) || coveringKeyframe(pose, frame.intrinsics) < 0;
}

std::vector<ViewId> ViewSelector::applyPointUpdates() {
  auto updates = points_->takeUpdates();
  for (const auto& [view, updated] : updates) {
    if (view < 0 || static_cast<size_t>(view) >= matrix_.size() || !updated.allFinite())
      throw InvalidInput("point source produced an invalid update for view " +
                         std::to_string(view));
  }
  std::vector<ViewId> rows;
  for (auto& [view, updated] : updates) {
    matrix_.setPoints(view, std::move(updated));
    neighbours_.update(view, matrix_.keyframe(view), config_.keyframes.keyframe_overlap);
    rows.push_back(view);
  }
  return rows;
}

void ViewSelector::correctPoses(const std::vector<std::pair<ViewId, CameraPose>>& poses) {
  matrix_.setPoses(poses);
  revisit_offset_.reset();  // measured against the poses as they were
  const ViewId last = static_cast<ViewId>(matrix_.size()) - 1;
  for (const auto& [id, pose] : poses) {
    neighbours_.update(id, matrix_.keyframe(id), config_.keyframes.keyframe_overlap);
    if (id == last) policy_.keyframeAccepted(matrix_.keyframe(id).pose);
  }
}

Selection ViewSelector::select() const {
  return selection_.update(matrix_.table(), config_.selection).toSelection();
}

SelectionOutput ViewSelector::output() const {
  SelectionOutput s;
  s.keyframes = matrix_.summaries();
  s.names = matrix_.imageNames();
  s.table = matrix_.table();
  s.selection = selection_.update(matrix_.table(), config_.selection);
  s.config = config_.selection;
  if (!params_) params_ = std::make_shared<const Params>(params());
  s.params = params_;
  return s;
}

void ViewSelector::setConfig(const ViewSelectorConfig& requested) {
  const ViewSelectorConfig config = inForce(requested);
  config.validate();
  policy_.setConfig(config.keyframes);
  matrix_.setConfig(config.matrix);
  const bool reindex = config.keyframes.keyframe_overlap != config_.keyframes.keyframe_overlap;
  config_ = config;
  if (reindex) indexNeighbours();
  params_.reset();
}

void ViewSelector::reset() {
  matrix_.clear();
  neighbours_.clear();
  revisits_skipped_ = revisits_registered_ = 0;
  revisit_offset_.reset();
  revisit_link_ = -1;
  if (registration_) registration_->clear();
  policy_.reset();
  points_->reset();
  last_stamp_.reset();
}

ViewSelectorState ViewSelector::state() const {
  ViewSelectorState s;
  s.config = config_;
  s.keyframes.reserve(matrix_.size());
  s.rows.reserve(matrix_.size());
  for (size_t i = 0; i < matrix_.size(); ++i) {
    s.keyframes.push_back(matrix_.keyframe(static_cast<ViewId>(i)));
    s.rows.push_back(matrix_.table().row(static_cast<ViewId>(i)));
  }
  s.policy = policy_.state();
  s.last_stamp = last_stamp_;
  return s;
}

void ViewSelector::restore(const ViewSelectorState& state) {
  state.config.validate();
  if (state.last_stamp && !std::isfinite(*state.last_stamp))
    throw InvalidInput("saved last stamp is not finite");
  ErrorResistanceMatrix matrix(state.config.matrix);
  matrix.restore(state.keyframes, state.rows);
  KeyframePolicy policy(state.config.keyframes);
  policy.restore(state.policy);
  config_ = inForce(state.config);
  matrix_ = std::move(matrix);
  policy_ = std::move(policy);
  last_stamp_ = state.last_stamp;
  // The saved keyframes have no images: later frames register to the new keyframes only.
  if (registration_) registration_->clear();
  revisit_offset_.reset();
  revisit_link_ = -1;
  indexNeighbours();
  params_.reset();
}

Params ViewSelector::params() const {
  Params out = paramsOf(config_);
  out.push_back({"point_source", points_->name(), false, {}});
  out.push_back({"point_source_params", false, true, points_->params()});
  return out;
}

}  // namespace view_selection::core
