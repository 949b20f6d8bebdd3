#include "view_selection/core/view_selector.h"

#include "view_selection/core/exceptions.h"

#include <chrono>
#include <cmath>
#include <sstream>

namespace view_selection {

namespace {
double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}
}  // namespace

void ViewSelectorConfig::validate() const {
  keyframes.validate();
  depth.validate();
  matrix.validate();
  selection.validate();
}

void validateFrame(const Frame& frame) {
  if (!std::isfinite(frame.stamp)) throw InvalidInput("frame stamp is not finite");
  const PinholeIntrinsics& k = frame.intrinsics;
  if (!k.isValid()) {
    std::ostringstream s;
    s << "camera intrinsics are unusable (fx=" << k.fx << ", fy=" << k.fy << ", cx=" << k.cx
      << ", cy=" << k.cy << ", size " << k.width << "x" << k.height
      << "): focal lengths must be positive and finite, the size non-zero";
    throw InvalidInput(s.str());
  }
  if (!frame.pose.isValid())
    throw InvalidInput("camera pose is not finite or its quaternion is not of unit length");
  if (!frame.depth_m.empty() && frame.depth_m.type() != CV_32FC1)
    throw InvalidInput("depth must be converted to CV_32FC1 metres (see depthToMetres)");
  if (!frame.depth_m.empty()) {
    // A depth image may be a scaled copy of the colour image, but with the same aspect ratio.
    const double ratio_image = static_cast<double>(k.width) / k.height;
    const double ratio_depth = static_cast<double>(frame.depth_m.cols) / frame.depth_m.rows;
    if (std::abs(ratio_image - ratio_depth) > 0.01 * ratio_image) {
      std::ostringstream s;
      s << "depth image is " << frame.depth_m.cols << "x" << frame.depth_m.rows
        << " but the camera is " << k.width << "x" << k.height << " (different aspect ratio)";
      throw InvalidInput(s.str());
    }
  }
  if (!frame.image.empty() && (frame.image.cols != k.width || frame.image.rows != k.height)) {
    std::ostringstream s;
    s << "image is " << frame.image.cols << "x" << frame.image.rows << " but camera_info says "
      << k.width << "x" << k.height;
    throw InvalidInput(s.str());
  }
}

ViewSelector::ViewSelector(ViewSelectorConfig config, std::unique_ptr<PointSource> points)
    : config_(std::move(config)),
      points_(points ? std::move(points) : std::make_unique<DepthPointSource>(config_.depth)),
      policy_(config_.keyframes),
      matrix_(config_.matrix) {
  config_.validate();
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

FrameResult ViewSelector::insert(const Frame& frame, const CameraPose& pose) {
  FrameResult result;
  if (!policy_.offer(pose)) return result;

  const auto t_points = std::chrono::steady_clock::now();
  const ViewId id = static_cast<ViewId>(matrix_.size());
  // The point source sees the same normalised pose as the matrix, so a caller's quaternion of
  // norm 1 +- rounding gives bit-identical points whichever path (node, tool) normalised it.
  Frame normalised = frame;  // cv::Mat members are shared, not copied
  normalised.pose = pose;
  PointSourceResult points = points_->process(id, normalised);
  if (!points.points.allFinite()) throw InvalidInput("point source produced non-finite points");
  for (const auto& [view, updated] : points.updated) {
    if (view < 0 || view >= id || !updated.allFinite())
      throw InvalidInput("point source produced an invalid update for view " + std::to_string(view));
  }
  result.points_seconds = secondsSince(t_points);

  Keyframe keyframe;
  keyframe.stamp = frame.stamp;
  keyframe.image_name = frame.image_name;
  keyframe.intrinsics = frame.intrinsics;
  keyframe.pose = pose;
  keyframe.points = std::move(points.points);
  if (config_.occlusion_test && !frame.depth_m.empty())
    keyframe.depth = std::make_shared<const DepthMap>(
        downsampleDepth(frame.depth_m, frame.intrinsics, config_.depth.depth_map_cell));
  result.points = static_cast<size_t>(keyframe.points.cols());

  // Nothing below throws for inputs validated above: the matrix is never left half-updated.
  const auto t_matrix = std::chrono::steady_clock::now();
  result.id = matrix_.addKeyframe(std::move(keyframe));
  for (auto& [view, updated] : points.updated) {
    matrix_.setPoints(view, std::move(updated));
    result.updated_rows.push_back(view);
  }
  result.matrix_seconds = secondsSince(t_matrix);
  policy_.keyframeAccepted(pose);
  result.outcome = FrameOutcome::kKeyframe;
  return result;
}

bool ViewSelector::wantsFrame(const CameraPose& pose) const {
  KeyframePolicy probe = policy_;
  return probe.offer(pose);
}

std::vector<ViewId> ViewSelector::applyPointUpdates() {
  auto updates = points_->takeUpdates();
  for (const auto& [view, updated] : updates) {
    if (view < 0 || static_cast<size_t>(view) >= matrix_.size() || !updated.allFinite())
      throw InvalidInput("point source produced an invalid update for view " + std::to_string(view));
  }
  std::vector<ViewId> rows;
  for (auto& [view, updated] : updates) {
    matrix_.setPoints(view, std::move(updated));
    rows.push_back(view);
  }
  return rows;
}

Selection ViewSelector::select() const { return selectViews(matrix_.table(), config_.selection); }

void ViewSelector::reset() {
  matrix_.clear();
  policy_.reset();
  points_->reset();
  last_stamp_.reset();
}

nlohmann::json ViewSelector::params() const {
  const auto& c = config_;
  return {
      {"k", c.selection.k},
      {"completion", toString(c.selection.completion)},
      {"point_source", points_->name()},
      {"keyframe_mode", toString(c.keyframes.mode)},
      {"every_n", c.keyframes.every_n},
      {"min_translation", c.keyframes.min_translation},
      {"min_rotation_deg", c.keyframes.min_rotation_deg},
      {"min_covisible_points", c.matrix.min_covisible_points},
      {"min_covisible_ratio", c.matrix.min_covisible_ratio},
      {"max_view_angle_deg", c.matrix.max_view_angle_deg},
      {"occlusion_test", c.occlusion_test},
      {"occlusion_abs_tolerance", c.matrix.occlusion_abs_tolerance},
      {"occlusion_rel_tolerance", c.matrix.occlusion_rel_tolerance},
      {"depth_grid_cols", c.depth.grid_cols},
      {"depth_grid_rows", c.depth.grid_rows},
      {"depth_min", c.depth.min_depth},
      {"depth_max", c.depth.max_depth},
      {"depth_min_valid_fraction", c.depth.min_valid_fraction},
      {"depth_pixel_stride", c.depth.pixel_stride},
      {"depth_map_cell", c.depth.depth_map_cell},
      {"point_source_params", points_->params()},
  };
}

}  // namespace view_selection
