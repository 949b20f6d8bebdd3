#include "view_selection/ros/keyframe_worker.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/sanitizers.h"
#include "view_selection/points/image_conversion.h"
#include "view_selection/points/map_point_source.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/ros/conversions.h"

#include <ros/console.h>

#include <sstream>

#if VS_THREAD_SANITIZER
#include <sanitizer/tsan_interface.h>
#endif

namespace view_selection::ros_node {

KeyframeWorker::KeyframeWorker(const NodeConfig& config, PoseProvider& poses,
                               InputStatistics& statistics, StateKeeper& keeper,
                               KeyframeVerdicts* verdicts, const PointSourceFactory& make_points,
                               PairStream* pairs, KeyframeImageWriter* image_writer)
    : config_(config),
      poses_(poses),
      statistics_(statistics),
      keeper_(keeper),
      verdicts_(verdicts),
      pairs_(pairs),
      image_writer_(image_writer) {
  selector_ = std::make_unique<core::ViewSelector>(
      config_.selector, make_points ? make_points(config_)
                                    : points::makePointSource(config_.point_source,
                                                              config_.point_params,
                                                              config_.selector.matrix.occlusion));
  if (config_.save_keyframe_images) {
    image_folder_ = std::make_shared<ImageFolder>(config_.image_dir);
    if (!image_folder_->error().empty())
      ROS_ERROR_STREAM("view_selection: ~image_dir: " << image_folder_->error()
                                                      << "; keyframe images beyond ~image_cache_mb "
                                                         "will be lost (not exported)");
    images_ = newImageCache();
  }
  selector_->trackPairChanges(pairs_ != nullptr);
  {
    std::lock_guard<std::timed_mutex> lock(state_mutex_);
    restoreLoaded();
    shareSelectionLocked();
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
  if (!keeper_.enabled()) return;
  std::optional<JournalSnapshot> record;
  std::optional<StateSnapshot> last;
  {
    std::lock_guard<std::timed_mutex> lock(state_mutex_);
    if (changed_since_save_) {
      if (keeper_.wantsFull())
        last = captureStateLocked();
      else
        record = captureDeltaLocked();
    }
  }
  if (record) {
    const SaveResult appended = keeper_.appendNow(std::move(*record));
    if (appended.ok) {
      ROS_INFO_STREAM("view_selection: session saved on shutdown: " << appended.message);
      return;
    }
    std::lock_guard<std::timed_mutex> lock(state_mutex_);
    last = captureStateLocked();  // the journal could not continue: a whole save
  }
  if (!last) return;
  const SaveResult saved = keeper_.saveNow(std::move(*last));
  if (saved.ok)
    ROS_INFO_STREAM("view_selection: session saved on shutdown: " << saved.message);
  else
    ROS_ERROR_STREAM("view_selection: " << saved.message);
}

std::shared_ptr<KeyframeImageCache> KeyframeWorker::newImageCache() const {
  return std::make_shared<KeyframeImageCache>(
      static_cast<size_t>(config_.image_cache_mb * 1024.0 * 1024.0), image_folder_);
}

void KeyframeWorker::restoreLoaded() {
  std::optional<io::SessionState> loaded = keeper_.takeLoaded();
  if (!loaded) return;
  try {
    io::restoreSession(*selector_, *loaded);
    saved_.markSaved(*selector_);  // what the file holds; a reconfigure below changes rows
    // The node's parameters win over the saved ones, as a live reconfigure would apply them
    // (compared as they act: the saved ones are the values in force, the gate's preset applied).
    core::ViewSelectorConfig wanted = config_.selector;
    wanted.matrix.applyGate();
    if (core::paramsOf(selector_->config()) != core::paramsOf(wanted)) {
      ROS_INFO(
          "view_selection: the saved session used other method parameters; applying this "
          "node's (the matrix is recomputed where its gates changed)");
      selector_->setConfig(config_.selector);
    }
  } catch (const core::Error& e) {
    selector_->reset();
    keeper_.refuseLoaded(e.what());
    return;
  }
  last_stamp_ = loaded->selector.last_stamp;
  if (pairs_) {
    // The continued session's pairs count as announced (a consumer catches up on the whole set
    // through ~get_pairs); the sequence goes on from the saved one.
    const core::SelectionOutput output = selector_->output();
    (void)selector_->takePairChanges();
    pairs_->restore(loaded->pair_sequence.value_or(0), output);
  }
  const size_t keyframes = selector_->matrix().size();
  keyframe_count_ = keyframes;
  // The state file keeps no images: the continued keyframes have none (null), later ones do.
  if (images_)
    for (size_t i = 0; i < keyframes; ++i) images_->push(nullptr);
  statistics_.restore(loaded->statistics, keyframes);
  const auto& last = loaded->statistics.last_frame_stamp;
  statistics_.stateSaved(static_cast<uint32_t>(keyframes),
                         last && *last > 0.0 ? ros::Time(*last) : ros::Time());
  // The restored session counts as saved: the file holds it.
  changed_since_save_ = false;
  ROS_INFO_STREAM(
      "view_selection: continuing the saved session: "
      << keyframes << " keyframes, " << loaded->statistics.frames_offered << " frames offered"
      << (last ? ", last frame at " + stampText(ros::Time(std::max(0.0, *last))) : std::string()));
}

void KeyframeWorker::push(PendingFrame frame) {
  std::optional<Queued> overflow;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    if (stopping_) return;
    // An image that arrived before a ~reset or a time jump: not part of the new session.
    if (frame.generation != generation_.load()) return;
    if (queue_.size() >= static_cast<size_t>(config_.max_pending_frames)) {
      overflow = std::move(queue_.front());
      queue_.pop_front();
    }
    // Counted under the lock reset() starts a new session under: a frame belongs to exactly one
    // session. No other lock: the inputs never wait for an insertion.
    const uint64_t session = statistics_.frameReceived();
    queue_.push_back({std::move(frame), generation_.load(), session, ros::WallTime::now()});
    queued_count_ = queue_.size();
  }
  if (pairs_) pairs_->frameSeen();
  queue_cv_.notify_one();
  if (overflow)
    drop(*overflow, "worker_behind",
         "the worker is " + std::to_string(config_.max_pending_frames) +
             " frames behind (~max_pending_frames); dropped the oldest waiting frame");
}

void KeyframeWorker::drop(const Queued& queued, const std::string& reason,
                          const std::string& message) {
  statistics_.drop(queued.session, reason, message, queued.frame.image->header.stamp);
  if (queued.generation == generation_.load()) changed_since_save_ = true;
}

size_t KeyframeWorker::pending(double* oldest_age) const {
  std::lock_guard<std::mutex> lock(queue_mutex_);
  if (oldest_age)
    *oldest_age = queue_.empty() ? 0.0 : (ros::WallTime::now() - queue_.front().queued).toSec();
  return queue_.size();
}

size_t KeyframeWorker::reset() {
  // The SLAM system's verdicts so far belong to the old session too (a waiting frame gives up).
  if (verdicts_) verdicts_->reset();
  return startSession(false);
}

void KeyframeWorker::timeJump(const ros::Time& newest, const ros::Time& stamp) {
  // Before the new session's first frame is queued: its pose and verdict come from the new
  // timeline only.
  poses_.newTimeline(stamp);
  if (verdicts_) verdicts_->newTimeline(stamp);
  const size_t forgotten = startSession(true);
  ROS_WARN_STREAM("view_selection: time jumped back from "
                  << stampText(newest) << " to " << stampText(stamp) << " ("
                  << core::formatNumber((newest - stamp).toSec())
                  << " s, more than ~time_jump_threshold " << config_.time_jump_threshold
                  << " s: a bag played again or looped, or a restarted SLAM system); a new session "
                     "starts, the old one's "
                  << forgotten << " keyframes "
                  << (keeper_.enabled() ? "are kept in " + keeper_.previousPath()
                                        : std::string("are forgotten (~state_file is empty)")));
}

std::optional<double> KeyframeWorker::lastStamp() const {
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  return last_stamp_;
}

size_t KeyframeWorker::startSession(bool time_jump) {
  std::shared_ptr<const ServedSelection> old;  // released after the locks
  size_t forgotten = 0;
  {
    std::lock_guard<std::mutex> queue_lock(queue_mutex_);
    queue_.clear();
    queued_count_ = 0;
    if (time_jump && keeper_.enabled()) {
      std::lock_guard<std::mutex> lock(aside_mutex_);
      // Frames of the old session still queued are discarded: its statistics are final here.
      if (!aside_) aside_ = Aside{generation_.load(), statistics_.toSaved()};
    }
    if (time_jump)
      statistics_.timeJump();
    else
      statistics_.reset();
    std::lock_guard<std::mutex> lock(served_mutex_);
    ++generation_;
    forgotten = keyframe_count_.exchange(0);
    // Empty at once, with the parameters in force; the worker's thread clears the selector
    // itself before its next frame (applyResetLocked) and shares its own empty selection then.
    auto empty = std::make_shared<ServedSelection>();
    empty->version = ++version_;
    empty->selection.config = served_->selection.config;
    empty->selection.params = served_->selection.params;
    old = std::move(served_);
    served_ = std::move(empty);
  }
  queue_cv_.notify_one();
  return forgotten;
}

void KeyframeWorker::applyResetLocked(uint64_t generation) {
  std::optional<Aside> aside;
  {
    std::lock_guard<std::mutex> lock(aside_mutex_);
    aside = std::move(aside_);
    aside_.reset();
  }
  // Only when the selector holds that session still (no ~reset came between).
  if (aside && aside->generation == applied_generation_) {
    StateSnapshot old = captureStateLocked();
    old.state.statistics = aside->statistics;
    keeper_.saveAside(std::move(old));
  }
  // Every pose a frame was given belongs to the old session (the worker looks poses up, so
  // none of the new one is recorded yet).
  poses_.clearHistory();
  selector_->reset();
  if (images_) images_ = newImageCache();  // selections shared before keep the old one
  last_stamp_.reset();
  keyframes_since_save_ = 0;
  applied_generation_ = generation;
  unshared_ = false;
  if (pairs_) {
    (void)selector_->takePairChanges();  // the old session's: a consumer starts over
    pairs_->reset(selector_->output());
  }
  shareSelectionLocked();
  keeper_.saveLater(captureStateLocked());
}

void KeyframeWorker::applyRequests() {
  std::optional<core::ViewSelectorConfig> config;
  uint64_t generation = 0;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    config = std::move(pending_config_);
    pending_config_.reset();
    generation = generation_.load();
  }
  if (generation == applied_generation_ && !config) return;
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  if (generation != applied_generation_) applyResetLocked(generation);
  if (config) {
    // Readers keep the selection shared last meanwhile (its lists are shared copy-on-write,
    // so recomputing E in place does not touch what they read).
    selector_->setConfig(*config);
    changed_since_save_ = true;
    shareSelectionLocked();
  }
}

StateSnapshot KeyframeWorker::captureState() {
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  return captureStateLocked();
}

StateSnapshot KeyframeWorker::captureStateLocked() {
  StateSnapshot s;
  s.sequence = ++captures_;
  s.state = io::captureSession(*selector_);
  s.state.statistics = statistics_.toSaved();
  s.state.saved_at = ros::WallTime::now().toSec();
  if (pairs_) s.state.pair_sequence = pairs_->sequence();
  saved_.markSaved(*selector_);
  changed_since_save_ = false;
  return s;
}

JournalSnapshot KeyframeWorker::captureDeltaLocked() {
  JournalSnapshot j;
  j.follows = captures_;
  j.sequence = ++captures_;
  j.delta = saved_.capture(*selector_);
  j.delta.rest.statistics = statistics_.toSaved();
  j.delta.rest.saved_at = ros::WallTime::now().toSec();
  if (pairs_) j.delta.rest.pair_sequence = pairs_->sequence();
  changed_since_save_ = false;
  return j;
}

void KeyframeWorker::setMapPoints(Eigen::Matrix3Xd points) {
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  auto* map = dynamic_cast<points::MapPointSource*>(&selector_->pointSource());
  if (!map) return;
  map->setMapPoints(std::move(points));
  const std::vector<core::ViewId> rows = selector_->applyPointUpdates();
  changed_since_save_ = true;
  if (!rows.empty()) shareSelectionLocked();
  ROS_DEBUG_STREAM("view_selection: map of " << map->mapPoints().cols() << " points, "
                                             << rows.size() << " keyframe rows recomputed");
}

void KeyframeWorker::reconfigure(const core::ViewSelectorConfig& config) {
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    pending_config_ = config;
  }
  queue_cv_.notify_one();
}

size_t KeyframeWorker::correctPoses(
    const std::vector<core::TimedPose>& corrections,
    const std::function<std::optional<core::CameraPose>(double)>& sourcePose,
    const core::PoseCorrectionConfig& config) {
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  const core::ErrorResistanceMatrix& m = selector_->matrix();
  std::vector<core::CorrectableKeyframe> keyframes;
  keyframes.reserve(m.size());
  for (size_t i = 0; i < m.size(); ++i) {
    const core::Keyframe& k = m.keyframe(static_cast<core::ViewId>(i));
    keyframes.push_back({k.stamp, k.pose, sourcePose(k.stamp).value_or(k.pose)});
  }
  const auto moves = core::matchCorrections(keyframes, corrections, config);
  if (moves.empty()) return 0;
  selector_->correctPoses(moves);
  shareSelectionLocked();
  return moves.size();
}

std::string KeyframeWorker::cameraFrame() const {
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  return camera_frame_;
}

std::shared_ptr<const ServedSelection> KeyframeWorker::served() const {
  std::lock_guard<std::mutex> lock(served_mutex_);
  return served_;
}

namespace {

/// lock.try_lock_for(seconds), told to ThreadSanitizer: libstdc++ takes a timed mutex with
/// pthread_mutex_clocklock, which TSan (gcc 12, clang 14) does not intercept, so the lock would
/// be invisible to it and every access made under it reported as a race.
bool tryLockFor(std::unique_lock<std::timed_mutex>& lock, double seconds) {
#if VS_THREAD_SANITIZER
  __tsan_mutex_pre_lock(lock.mutex(), __tsan_mutex_try_lock);
  const bool locked = lock.try_lock_for(std::chrono::duration<double>(seconds));
  __tsan_mutex_post_lock(lock.mutex(),
                         __tsan_mutex_try_lock | (locked ? 0u : __tsan_mutex_try_lock_failed), 0);
  return locked;
#else
  return lock.try_lock_for(std::chrono::duration<double>(seconds));
#endif
}

}  // namespace

std::shared_ptr<const ServedSelection> KeyframeWorker::servedLatest() {
  if (unshared_) {
    std::unique_lock<std::timed_mutex> lock(state_mutex_, std::defer_lock);
    if (tryLockFor(lock, kLatestWait) && unshared_) shareSelectionLocked();
  }
  return served();
}

void KeyframeWorker::shareSelectionLocked() {
  auto next = std::make_shared<ServedSelection>();
  next->selection = selector_->output();  // O(what changed): the lists' chunks are shared
  if (pairs_) pairs_->update(selector_->takePairChanges(), next->selection);
  next->images = images_;
  next->image_count = images_ ? images_->size() : 0;
  unshared_ = false;
  last_share_ = ros::WallTime::now();
  installServed(std::move(next), applied_generation_);
}

void KeyframeWorker::installServed(std::shared_ptr<ServedSelection> next, uint64_t generation) {
  std::shared_ptr<const ServedSelection> old;  // released after the lock
  {
    std::lock_guard<std::mutex> lock(served_mutex_);
    if (generation != generation_.load()) return;  // a reset since: its empty selection stays
    next->version = ++version_;
    old = std::move(served_);
    served_ = std::move(next);
  }
}

void KeyframeWorker::keyframeInsertedLocked() {
  if (applied_generation_ == generation_.load()) keyframe_count_ = selector_->matrix().size();
  // While frames wait, shares are coalesced (at most kMaxShareInterval apart); a service that
  // wants the newest keyframe meanwhile asks for it (servedLatest).
  if (queued_count_.load() == 0 ||
      (ros::WallTime::now() - last_share_).toSec() >= kMaxShareInterval)
    shareSelectionLocked();
  else
    unshared_ = true;
}

void KeyframeWorker::loop() {
  while (true) {
    applyRequests();
    Queued queued;
    {
      std::unique_lock<std::mutex> lock(queue_mutex_);
      if (queue_.empty() && unshared_) {
        // Idle with keyframes not shared yet: share them before waiting.
        lock.unlock();
        {
          std::lock_guard<std::timed_mutex> state(state_mutex_);
          if (unshared_) shareSelectionLocked();
        }
        lock.lock();
      }
      queue_cv_.wait(lock, [this] {
        return stopping_ || !queue_.empty() || pending_config_ ||
               generation_.load() != applied_generation_;
      });
      if (stopping_) return;
      if (queue_.empty()) continue;  // a request: applied at the top
      queued = std::move(queue_.front());
      queue_.pop_front();
      queued_count_ = queue_.size();
    }
    try {
      process(queued);
    } catch (const std::exception& e) {
      // process() turns every expected failure into a drop; this is the last line of defence.
      drop(queued, "invalid_frame", std::string("unexpected error: ") + e.what());
    }
  }
}

bool KeyframeWorker::convert(const Queued& queued, CameraModel& camera) {
  const PendingFrame& frame = queued.frame;
  const sensor_msgs::Image& image = *frame.image;
  try {
    checkImageMessage(image, "image");
  } catch (const core::InvalidInput& e) {
    drop(queued, "bad_image", e.what());
    return false;
  }
  if (frame.depth) {
    try {
      checkImageMessage(*frame.depth, "depth");
      checkDepthEncoding(*frame.depth);
    } catch (const core::InvalidInput& e) {
      drop(queued, "bad_depth", e.what());
      return false;
    }
    // Depth sampled at colour pixels must be registered to the colour camera.
    const std::string depth_frame = normaliseFrameId(frame.depth->header.frame_id);
    const std::string image_frame = normaliseFrameId(image.header.frame_id);
    if (!depth_frame.empty() && !image_frame.empty() && depth_frame != image_frame) {
      drop(queued, "bad_depth",
           "the depth image is in frame '" + depth_frame + "', not the colour image's '" +
               image_frame +
               "': use depth registered to the colour camera (e.g. depth_registered, "
               "aligned_depth_to_color)");
      return false;
    }
  }
  try {
    camera = cameraModelFromInfo(*frame.info);
  } catch (const core::InvalidInput& e) {
    drop(queued, "bad_camera_info", e.what());
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
    drop(queued, "bad_camera_info", s.str());
    return false;
  }
  return true;
}

void KeyframeWorker::process(const Queued& queued) {
  if (pairs_) pairs_->frameSeen();  // handled frames count as seen too (a backlog is no pause)
  const PendingFrame& frame = queued.frame;
  const ros::Time stamp = frame.image->header.stamp;
  // The stamp first: a frame repeated or late is dropped for that, whatever else is wrong with
  // it (a repeated stamp may also have been paired with the earlier frame's depth).
  {
    std::lock_guard<std::timed_mutex> lock(state_mutex_);
    if (queued.generation != generation_.load()) return;  // queued before a reset
    if (queued.generation != applied_generation_) applyResetLocked(queued.generation);
    if (last_stamp_ && !(stamp.toSec() > *last_stamp_)) {
      const bool duplicate = stamp.toSec() == *last_stamp_;
      std::ostringstream s;
      s << "stamp " << stampText(stamp) << " is " << (duplicate ? "the same as" : "before")
        << " the previous frame's " << stampText(ros::Time(*last_stamp_));
      statistics_.drop(queued.session, duplicate ? "duplicate_stamp" : "out_of_order_stamp",
                       s.str(), stamp);
      changed_since_save_ = true;
      return;
    }
  }
  CameraModel camera;
  if (!convert(queued, camera)) return;
  {
    std::lock_guard<std::timed_mutex> lock(state_mutex_);
    if (queued.generation != generation_.load()) return;
    camera_frame_ = normaliseFrameId(frame.image->header.frame_id);
  }
  // The waits for the verdict and the pose hold no lock: services and resets go on meanwhile.
  bool external = false;
  if (verdicts_ && verdicts_->active()) {
    const KeyframeVerdicts::Verdict verdict = verdicts_->wait(stamp);
    if (verdict == KeyframeVerdicts::Verdict::kUnknown)
      return drop(queued, "no_keyframe_verdict",
                  "no stamp on " + verdicts_->describe() + " at or after " + stampText(stamp) +
                      " within " + std::to_string(config_.keyframe_verdict_timeout) +
                      " s (~keyframe_verdict_timeout): the frame's verdict is unknown");
    external = verdict == KeyframeVerdicts::Verdict::kKeyframe;
  }
  const PoseLookup lookup = poses_.lookup(normaliseFrameId(frame.image->header.frame_id), stamp);
  if (!lookup.pose) return drop(queued, lookup.reason, lookup.message);
  if (!lookup.pose->isValid())
    return drop(queued, "bad_pose",
                "the camera pose is not finite or its quaternion is not unit length");

  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  // A reset while the pose was looked up: the frame belongs to the forgotten session.
  if (queued.generation != generation_.load() || queued.generation != applied_generation_) return;
  // Drops from here on are under the state lock: counted directly, the session marked changed.
  auto dropLocked = [&](const std::string& reason, const std::string& message) {
    statistics_.drop(queued.session, reason, message, stamp);
    changed_since_save_ = true;
  };
  if (last_stamp_ && !(stamp.toSec() > *last_stamp_))
    return dropLocked("out_of_order_stamp",
                      "stamp " + stampText(stamp) + " is not after the previous frame's");
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
  const bool wanted = selector_->wantsFrame(core_frame);
  try {
    core_frame.image = wanted ? colourImageForCore(frame.image) : borrowedImageView(frame.image);
    // Distortion applied: the core's pinhole model holds for the rectified image only.
    if (wanted && camera.rectify)
      core_frame.image =
          points::colourImageOf(rectifiedImage(camera, points::matOf(core_frame.image)));
  } catch (const core::InvalidInput& e) {
    return dropLocked("bad_image", e.what());
  }
  // Feature points use the image alone (as select_views --points features reads no depth).
  if (wanted && frame.depth && config_.point_source != "features") {
    try {
      cv::Mat metres = depthToMetres(*frame.depth, config_.depth_16u_metres_per_unit);
      if (camera.rectify) metres = rectifiedDepth(camera, metres);
      core_frame.depth = points::depthImageOf(metres);
    } catch (const core::InvalidInput& e) {
      return dropLocked("bad_depth", e.what());
    }
  }
  core::FrameResult result;
  try {
    result = selector_->addFrame(core_frame);
  } catch (const core::InvalidInput& e) {
    return dropLocked("invalid_frame", e.what());
  }
  last_stamp_ = core_frame.stamp;
  changed_since_save_ = true;
  double insertion = -1.0;
  if (result.outcome == core::FrameOutcome::kKeyframe) {
    // A distorted camera's keyframe images are kept rectified, as the exported intrinsics are.
    sensor_msgs::ImageConstPtr kept;
    if (images_ || image_writer_)
      kept = camera.rectify ? rectifiedImageMessage(camera, frame.image) : frame.image;
    if (images_) images_->push(kept);
    if (image_writer_) image_writer_->push(core_frame.image_name, kept);
    insertion = result.points_seconds + result.matrix_seconds;
    // Counted before the selection is shared: a reader never sees more keyframes in the
    // selection than in the statistics.
    statistics_.frameOffered(queued.session, stamp, insertion);
    keyframeInsertedLocked();
    ROS_DEBUG_STREAM("view_selection: keyframe "
                     << result.id << " at " << stampText(stamp) << ": " << result.points
                     << " points, insertion " << 1e3 * insertion << " ms (points "
                     << 1e3 * result.points_seconds << " ms, matrix " << 1e3 * result.matrix_seconds
                     << " ms), " << selector_->matrix().size() << " keyframes");
    if (config_.autosave_keyframes > 0 && ++keyframes_since_save_ >= config_.autosave_keyframes &&
        keeper_.enabled()) {
      keyframes_since_save_ = 0;
      // Only what changed since the last save, appended to the journal on the keeper's thread;
      // a whole copy when the journal cannot continue (no base yet, a failed write).
      if (keeper_.wantsFull())
        keeper_.saveLater(captureStateLocked());
      else
        keeper_.appendLater(captureDeltaLocked());
    }
    return;
  }
  statistics_.frameOffered(queued.session, stamp, insertion);
}

}  // namespace view_selection::ros_node
