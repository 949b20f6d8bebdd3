#include "view_selection/ros/keyframe_worker.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/points/image_conversion.h"
#include "view_selection/points/map_point_source.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/ros/conversions.h"

#include <ros/console.h>

#include <sstream>

namespace view_selection::ros_node {

KeyframeWorker::KeyframeWorker(const NodeConfig& config, PoseProvider& poses,
                               InputStatistics& statistics, KeyframeVerdicts* verdicts)
    : config_(config), poses_(poses), statistics_(statistics), verdicts_(verdicts) {
  selector_ = std::make_unique<core::ViewSelector>(
      config_.selector, points::makePointSource(config_.point_source, config_.point_params,
                                                config_.selector.matrix.occlusion));
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    publishSnapshotLocked();
  }
  thread_ = std::thread([this] { loop(); });
}

KeyframeWorker::~KeyframeWorker() {
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    stopping_ = true;
  }
  queue_cv_.notify_all();
  poses_.stop();
  if (verdicts_) verdicts_->stop();
  if (thread_.joinable()) thread_.join();
}

void KeyframeWorker::push(PendingFrame frame) {
  std::optional<Queued> overflow;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    if (stopping_) return;
    if (queue_.size() >= static_cast<size_t>(config_.max_pending_frames)) {
      overflow = std::move(queue_.front());
      queue_.pop_front();
    }
    std::lock_guard<std::mutex> state(state_mutex_);
    queue_.push_back({std::move(frame), generation_, ros::WallTime::now()});
  }
  queue_cv_.notify_one();
  if (overflow)
    statistics_.drop("worker_behind",
                     "the worker is " + std::to_string(config_.max_pending_frames) +
                         " frames behind (~max_pending_frames); dropped the oldest waiting frame",
                     overflow->frame.image->header.stamp);
}

size_t KeyframeWorker::pending(double* oldest_age) const {
  std::lock_guard<std::mutex> lock(queue_mutex_);
  if (oldest_age)
    *oldest_age = queue_.empty() ? 0.0 : (ros::WallTime::now() - queue_.front().queued).toSec();
  return queue_.size();
}

size_t KeyframeWorker::reset() {
  std::lock_guard<std::mutex> queue_lock(queue_mutex_);
  std::lock_guard<std::mutex> lock(state_mutex_);
  queue_.clear();
  const size_t forgotten = selector_->matrix().size();
  selector_->reset();
  images_.clear();
  last_stamp_.reset();
  ++generation_;
  publishSnapshotLocked();
  return forgotten;
}

void KeyframeWorker::setMapPoints(Eigen::Matrix3Xd points) {
  std::lock_guard<std::mutex> lock(state_mutex_);
  auto* map = dynamic_cast<points::MapPointSource*>(&selector_->pointSource());
  if (!map) return;
  map->setMapPoints(std::move(points));
  const std::vector<core::ViewId> rows = selector_->applyPointUpdates();
  if (!rows.empty()) publishSnapshotLocked();
  ROS_DEBUG_STREAM("view_selection: map of " << map->mapPoints().cols() << " points, "
                                             << rows.size() << " keyframe rows recomputed");
}

void KeyframeWorker::reconfigure(const core::ViewSelectorConfig& config) {
  std::lock_guard<std::mutex> lock(state_mutex_);
  selector_->setConfig(config);
  publishSnapshotLocked();
}

size_t KeyframeWorker::correctPoses(const std::vector<core::TimedPose>& trajectory,
                                    const core::PoseCorrectionConfig& config) {
  std::lock_guard<std::mutex> lock(state_mutex_);
  const core::ErrorResistanceMatrix& m = selector_->matrix();
  std::vector<core::TimedPose> keyframes;
  keyframes.reserve(m.size());
  for (size_t i = 0; i < m.size(); ++i) {
    const core::Keyframe& k = m.keyframe(static_cast<core::ViewId>(i));
    keyframes.push_back({k.stamp, k.pose});
  }
  const auto moves = core::matchCorrections(keyframes, trajectory, config);
  if (moves.empty()) return 0;
  selector_->correctPoses(moves);
  publishSnapshotLocked();
  return moves.size();
}

std::string KeyframeWorker::cameraFrame() const {
  std::lock_guard<std::mutex> lock(state_mutex_);
  return camera_frame_;
}

std::shared_ptr<const NodeSnapshot> KeyframeWorker::snapshot() const {
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  return snapshot_;
}

void KeyframeWorker::publishSnapshotLocked() {
  auto next = std::make_shared<NodeSnapshot>();
  next->version = ++version_;
  next->selection = selector_->snapshot();
  next->images = images_;
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  snapshot_ = std::move(next);
}

void KeyframeWorker::loop() {
  while (true) {
    Queued queued;
    {
      std::unique_lock<std::mutex> lock(queue_mutex_);
      queue_cv_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      queued = std::move(queue_.front());
      queue_.pop_front();
    }
    try {
      process(queued);
    } catch (const std::exception& e) {
      // process() turns every expected failure into a drop; this is the last line of defence.
      statistics_.drop("invalid_frame", std::string("unexpected error: ") + e.what(),
                       queued.frame.image->header.stamp);
    }
  }
}

bool KeyframeWorker::convert(const PendingFrame& frame, CameraModel& camera) {
  const sensor_msgs::Image& image = *frame.image;
  const ros::Time stamp = image.header.stamp;
  try {
    checkImageMessage(image, "image");
  } catch (const core::InvalidInput& e) {
    statistics_.drop("bad_image", e.what(), stamp);
    return false;
  }
  if (frame.depth) {
    try {
      checkImageMessage(*frame.depth, "depth");
      checkDepthEncoding(*frame.depth);
    } catch (const core::InvalidInput& e) {
      statistics_.drop("bad_depth", e.what(), stamp);
      return false;
    }
    // Depth sampled at colour pixels must be registered to the colour camera.
    const std::string depth_frame = normaliseFrameId(frame.depth->header.frame_id);
    const std::string image_frame = normaliseFrameId(image.header.frame_id);
    if (!depth_frame.empty() && !image_frame.empty() && depth_frame != image_frame) {
      statistics_.drop("bad_depth",
                       "the depth image is in frame '" + depth_frame +
                           "', not the colour "
                           "image's '" +
                           image_frame +
                           "': use depth registered to the colour camera (e.g. "
                           "depth_registered, aligned_depth_to_color)",
                       stamp);
      return false;
    }
  }
  try {
    camera = cameraModelFromInfo(*frame.info);
  } catch (const core::InvalidInput& e) {
    statistics_.drop("bad_camera_info", e.what(), stamp);
    return false;
  }
  const core::PinholeIntrinsics& k = camera.intrinsics;
  if (image.width != static_cast<uint32_t>(k.width) ||
      image.height != static_cast<uint32_t>(k.height)) {
    std::ostringstream s;
    s << "image is " << image.width << "x" << image.height << " but camera_info says " << k.width
      << "x" << k.height
      << (frame.info->binning_x > 1 || frame.info->binning_y > 1 || frame.info->roi.width > 0
              ? " (with its binning and ROI)"
              : "");
    statistics_.drop("bad_camera_info", s.str(), stamp);
    return false;
  }
  return true;
}

void KeyframeWorker::process(const Queued& queued) {
  const PendingFrame& frame = queued.frame;
  const ros::Time stamp = frame.image->header.stamp;
  CameraModel camera;
  if (!convert(frame, camera)) return;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    if (queued.generation != generation_) return;  // queued before a reset
    camera_frame_ = normaliseFrameId(frame.image->header.frame_id);
    if (last_stamp_ && !(stamp.toSec() > *last_stamp_)) {
      const bool duplicate = stamp.toSec() == *last_stamp_;
      std::ostringstream s;
      s << "stamp " << stampText(stamp) << " is " << (duplicate ? "the same as" : "before")
        << " the previous frame's " << stampText(ros::Time(*last_stamp_));
      statistics_.drop(duplicate ? "duplicate_stamp" : "out_of_order_stamp", s.str(), stamp);
      return;
    }
  }
  // The waits for the verdict and the pose hold no lock: services and resets go on meanwhile.
  bool external = false;
  if (verdicts_ && verdicts_->active()) {
    const KeyframeVerdicts::Verdict verdict = verdicts_->wait(stamp);
    if (verdict == KeyframeVerdicts::Verdict::kUnknown)
      return statistics_.drop("no_keyframe_verdict",
                              "no stamp on " + verdicts_->describe() + " at or after " +
                                  stampText(stamp) + " within " +
                                  std::to_string(config_.keyframe_verdict_timeout) +
                                  " s (~keyframe_verdict_timeout): the frame's verdict is unknown",
                              stamp);
    external = verdict == KeyframeVerdicts::Verdict::kKeyframe;
  }
  const PoseLookup lookup = poses_.lookup(normaliseFrameId(frame.image->header.frame_id), stamp);
  if (!lookup.pose) return statistics_.drop(lookup.reason, lookup.message, stamp);
  if (!lookup.pose->isValid())
    return statistics_.drop(
        "bad_pose", "the camera pose is not finite or its quaternion is not unit length", stamp);

  std::lock_guard<std::mutex> lock(state_mutex_);
  // A reset while the pose was looked up: the frame belongs to the forgotten session.
  if (queued.generation != generation_) return;
  if (last_stamp_ && !(stamp.toSec() > *last_stamp_))
    return statistics_.drop("out_of_order_stamp",
                            "stamp " + stampText(stamp) + " is not after the previous frame's",
                            stamp);
  core::Frame core_frame;
  core_frame.stamp = stamp.toSec();
  core_frame.image_name = keyframeImageName(core_frame.stamp);
  core_frame.intrinsics = camera.intrinsics;
  core_frame.pose = *lookup.pose;
  core_frame.external_keyframe = external;
  // Normalised here as the TUM reader normalises groundtruth.txt, so that for the same frames the
  // point source sees bit-identical rotations and the matrix equals select_views' exactly.
  core_frame.pose.orientation.normalize();
  // As select_views does: only frames the policy will take get their images converted.
  const bool wanted = selector_->wantsFrame(core_frame.pose, external);
  try {
    core_frame.image = wanted ? colourImageForCore(frame.image) : borrowedImageView(frame.image);
    // Distortion applied: the core's pinhole model holds for the rectified image only.
    if (wanted && camera.rectify)
      core_frame.image =
          points::colourImageOf(rectifiedImage(camera, points::matOf(core_frame.image)));
  } catch (const core::InvalidInput& e) {
    return statistics_.drop("bad_image", e.what(), stamp);
  }
  // Feature points use the image alone (as select_views --points features reads no depth).
  if (wanted && frame.depth && config_.point_source != "features") {
    try {
      cv::Mat metres = depthToMetres(*frame.depth, config_.depth_16u_metres_per_unit);
      if (camera.rectify) metres = rectifiedDepth(camera, metres);
      core_frame.depth = points::depthImageOf(metres);
    } catch (const core::InvalidInput& e) {
      return statistics_.drop("bad_depth", e.what(), stamp);
    }
  }
  core::FrameResult result;
  try {
    result = selector_->addFrame(core_frame);
  } catch (const core::InvalidInput& e) {
    return statistics_.drop("invalid_frame", e.what(), stamp);
  }
  last_stamp_ = core_frame.stamp;
  double insertion = -1.0;
  if (result.outcome == core::FrameOutcome::kKeyframe) {
    if (config_.save_keyframe_images) images_.push_back(frame.image);
    publishSnapshotLocked();
    insertion = result.points_seconds + result.matrix_seconds;
    ROS_DEBUG_STREAM("view_selection: keyframe "
                     << result.id << " at " << stampText(stamp) << ": " << result.points
                     << " points, insertion " << 1e3 * insertion << " ms (points "
                     << 1e3 * result.points_seconds << " ms, matrix " << 1e3 * result.matrix_seconds
                     << " ms), " << selector_->matrix().size() << " keyframes");
  }
  statistics_.frameOffered(insertion);
}

}  // namespace view_selection::ros_node
