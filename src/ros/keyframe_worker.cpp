#include "view_selection/ros/keyframe_worker.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/sanitizers.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/points/map_point_source.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/registration/orb_registration.h"
#include "view_selection/ros/conversions.h"
#include "view_selection/ros/frame_checks.h"

#include <ros/console.h>

#include <algorithm>
#include <sstream>

#if VS_THREAD_SANITIZER
#include <sanitizer/tsan_interface.h>
#endif

namespace view_selection::ros_node {

namespace {

// The revisit rule under drift registers frames from their images (scale_free with
// ~revisit_registration only; docs/design.md, "Revisits under drift"): the selector owns the
// registration, the worker keeps what it knows of the keyframes in the registration log.
core::FrameRegistration& attachRegistration(core::ViewSelector& selector) {
  auto orb = std::make_unique<registration::OrbRegistration>();
  core::FrameRegistration& kept = *orb;
  selector.setRegistration(std::move(orb));
  return kept;
}

std::unique_ptr<core::PointSource> makePoints(const NodeConfig& config,
                                              const PointSourceFactory& make_points) {
  return make_points ? make_points(config)
                     : points::makePointSource(config.point_source, config.point_params,
                                               config.selector.matrix.occlusion);
}

}  // namespace

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
      selector_(std::make_unique<core::ViewSelector>(config_.selector,
                                                     makePoints(config_, make_points))),
      intake_(static_cast<size_t>(config_.max_pending_frames), statistics_, generation_),
      shared_(generation_),
      handoff_(config_, keeper_, statistics_, pairs_),
      images_(config_, image_writer),
      registration_log_(keeper_.path(), attachRegistration(*selector_)) {
  selector_->trackPairChanges(pairs_ != nullptr);
  {
    std::lock_guard<std::timed_mutex> lock(state_mutex_);
    restoreLoaded();
    shareSelectionLocked();
  }
  thread_ = std::thread([this] { loop(); });
}

KeyframeWorker::~KeyframeWorker() {
  // The frames still queued are handled before the thread ends: with the pose source and the
  // verdicts stopped, none waits; each becomes a keyframe, a non-keyframe or a counted drop.
  intake_.stop();
  poses_.stop();
  if (verdicts_) verdicts_->stop();
  if (thread_.joinable()) thread_.join();
  handoff_.saveOnShutdown(*selector_, state_mutex_);
}

void KeyframeWorker::restoreLoaded() {
  const std::optional<session::SessionState> loaded =
      handoff_.continueLoaded(*selector_, config_.selector);
  if (!loaded) return startRegistrationLog(false);
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
  // The state file keeps no images: the continued keyframes have none, later ones do. What the
  // registration kept of them is in its own log.
  images_.continued(keyframes);
  startRegistrationLog(true);
  statistics_.restore(loaded->statistics, keyframes);
  const auto& last = loaded->statistics.last_frame_stamp;
  statistics_.stateSaved(static_cast<uint32_t>(keyframes),
                         last && *last > 0.0 ? ros::Time(*last) : ros::Time());
  ROS_INFO_STREAM(
      "view_selection: continuing the saved session: "
      << keyframes << " keyframes, " << loaded->statistics.frames_offered << " frames offered"
      << (last ? ", last frame at " + stampText(ros::Time(std::max(0.0, *last))) : std::string()));
}

void KeyframeWorker::startRegistrationLog(bool continued) {
  if (registration_log_.path().empty()) return;
  if (!continued) {
    const std::string error = registration_log_.startSession();
    if (!error.empty())
      ROS_WARN_STREAM("view_selection: " << error
                                         << ": after a restart, revisits are recognised only of "
                                            "the keyframes made after it");
    return;
  }
  const session::RegistrationLog::Continued c =
      registration_log_.continueSession(selector_->matrix());
  if (!c.error.empty()) ROS_WARN_STREAM("view_selection: " << c.error);
  if (c.restored + c.dropped + c.unread == 0 && !config_.selector.keyframes.revisit_registration)
    return;
  ROS_INFO_STREAM("view_selection: the revisit rule's features of "
                  << c.restored << " of the " << selector_->matrix().size()
                  << " continued keyframes read from " << registration_log_.path()
                  << (c.dropped + c.unread > 0
                          ? " (" + std::to_string(c.dropped) + " records of no such keyframe and " +
                                std::to_string(c.unread) + " unreadable bytes dropped)"
                          : std::string()));
}

void KeyframeWorker::push(PendingFrame frame) {
  FrameQueue::Pushed pushed = intake_.push(std::move(frame));
  if (!pushed.queued) return;
  if (pairs_) pairs_->frameSeen();
  if (pushed.overflow)
    drop(*pushed.overflow, "worker_behind",
         "the worker is " + std::to_string(config_.max_pending_frames) +
             " frames behind (~max_pending_frames); dropped the oldest waiting frame");
}

void KeyframeWorker::drop(const QueuedFrame& queued, const std::string& reason,
                          const std::string& message) {
  statistics_.drop(queued.session, reason, message, queued.frame.image->header.stamp);
  if (queued.generation == generation_.load()) handoff_.markChanged();
}

size_t KeyframeWorker::pending(double* oldest_age) const { return intake_.pending(oldest_age); }

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
  intake_.startGeneration([&] {  // under the queue lock, the waiting frames forgotten
    if (time_jump) {
      handoff_.keepAside(generation_.load());  // the old session, under the aside lock
      statistics_.timeJump();
    } else {
      statistics_.reset();
    }
    old = shared_.serveEmpty([&] {  // under the served lock
      ++generation_;
      forgotten = keyframe_count_.exchange(0);
    });
  });
  return forgotten;
}

void KeyframeWorker::applyResetLocked(uint64_t generation) {
  handoff_.beforeClear(*selector_, applied_generation_);  // a time jump's session kept aside
  // Every pose a frame was given belongs to the old session (the worker looks poses up, so
  // none of the new one is recorded yet).
  poses_.clearHistory();
  selector_->reset();
  startRegistrationLog(false);
  images_.newSession();  // selections shared before keep the old images
  last_stamp_.reset();
  later_corrections_.clear();  // the old session's world
  applied_generation_ = generation;
  unshared_ = false;
  if (pairs_) {
    (void)selector_->takePairChanges();  // the old session's: a consumer starts over
    pairs_->reset(selector_->output());
  }
  shareSelectionLocked();
  handoff_.afterClear(*selector_);  // the empty session saved
}

void KeyframeWorker::applyRequests() {
  FrameQueue::Requests r = intake_.takeRequests();
  if (r.generation == applied_generation_ && !r.config && !r.map && r.saves.empty()) return;
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  if (r.generation != applied_generation_) applyResetLocked(r.generation);
  if (r.config) {
    // Readers keep the selection shared last meanwhile (its lists are shared copy-on-write,
    // so recomputing E in place does not touch what they read).
    selector_->setConfig(*r.config);
    handoff_.markChanged();
    shareSelectionLocked();
  }
  if (r.map) applyMapLocked(std::move(*r.map));
  for (const auto& save : r.saves) save();
}

void KeyframeWorker::requestSave(std::function<void(const SaveResult&)> done) {
  if (!keeper_.enabled()) {
    done({false, "~state_file is empty: saving is off", 0, 0.0});
    return;
  }
  // Captured on the worker's thread (under the state lock, which no service thread takes),
  // written on the keeper's.
  intake_.requestSave([this, done = std::move(done)] {
    keeper_.saveLater(handoff_.captureWhole(*selector_), done);
  });
}

void KeyframeWorker::setMapPoints(Eigen::Matrix3Xd points) {
  if (!points.allFinite()) throw core::InvalidInput("map points must be finite");
  intake_.setMap(std::move(points));
}

void KeyframeWorker::applyMapLocked(Eigen::Matrix3Xd points) {
  points::MapPointSource* map = points::mapSourceOf(selector_->pointSource());
  if (!map) return;
  try {
    map->setMapPoints(std::move(points));
  } catch (const core::InvalidInput& e) {
    statistics_.dropInput("bad_map", std::string("ignored the map: ") + e.what(), ros::Time());
    return;
  }
  const std::vector<core::ViewId> rows = selector_->applyPointUpdates();
  handoff_.markChanged();
  if (!rows.empty()) shareSelectionLocked();
  ROS_DEBUG_STREAM("view_selection: map of " << map->mapPoints().cols() << " points, "
                                             << rows.size() << " keyframe rows recomputed");
}

void KeyframeWorker::reconfigure(const core::ViewSelectorConfig& config) {
  intake_.reconfigure(config);
}

size_t KeyframeWorker::correctPoses(
    const std::vector<core::TimedPose>& corrections,
    const std::function<std::optional<core::CameraPose>(double)>& sourcePose,
    const core::PoseCorrectionConfig& config) {
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  const core::ErrorResistanceMatrix& m = selector_->matrix();
  std::vector<core::CorrectableKeyframe> keyframes;
  keyframes.reserve(m.size());
  // Corrections measured in ~odom_frame apply to poses in it: a keyframe without one (continued
  // from ~state_file) keeps its pose, where one in world_frame takes the correction applied to it.
  const bool own_frame = config_.correctionFrame().empty();
  std::vector<bool> without_source(m.size(), false);
  for (size_t i = 0; i < m.size(); ++i) {
    const core::Keyframe& k = m.keyframe(static_cast<core::ViewId>(i));
    const std::optional<core::CameraPose> source = sourcePose(k.stamp);
    without_source[i] = !source && !own_frame;
    keyframes.push_back({k.stamp, k.pose, source.value_or(k.pose)});
  }
  auto moves = core::matchCorrections(keyframes, corrections, config);
  moves.erase(std::remove_if(moves.begin(), moves.end(),
                             [&](const auto& move) { return without_source[move.first]; }),
              moves.end());
  // The frames still to come are in the source's frame, as the keyframes' source poses are: a
  // later path's corrections are measured against the source's history, so they replace these.
  if (config_.correct_later_frames && !corrections.empty()) later_corrections_ = corrections;
  if (moves.empty()) return 0;
  selector_->correctPoses(moves);
  shareSelectionLocked();
  return moves.size();
}

std::string KeyframeWorker::cameraFrame() const {
  std::lock_guard<std::timed_mutex> lock(state_mutex_);
  return camera_frame_;
}

std::shared_ptr<const ServedSelection> KeyframeWorker::served() const { return shared_.get(); }

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
  next->images = images_.cache();
  next->image_count = images_.count();
  unshared_ = false;
  last_share_ = ros::WallTime::now();
  const size_t keyframes = next->selection.size();
  shared_.install(std::move(next), applied_generation_);
  images_.shared(keyframes);  // after the install: a folder switch finds them served
}

void KeyframeWorker::keyframeInsertedLocked() {
  if (applied_generation_ == generation_.load()) keyframe_count_ = selector_->matrix().size();
  // While frames wait, shares are coalesced (at most kMaxShareInterval apart); a service that
  // wants the newest keyframe meanwhile asks for it (servedLatest).
  if (intake_.queuedCount() == 0 ||
      (ros::WallTime::now() - last_share_).toSec() >= kMaxShareInterval)
    shareSelectionLocked();
  else
    unshared_ = true;
}

void KeyframeWorker::loop() {
  // Idle with keyframes not shared yet: share them before waiting.
  const auto idle = [this] {
    if (!unshared_) return;
    std::lock_guard<std::timed_mutex> state(state_mutex_);
    if (unshared_) shareSelectionLocked();
  };
  while (true) {
    applyRequests();
    bool stop = false;
    const std::optional<QueuedFrame> queued = intake_.next(applied_generation_, idle, &stop);
    if (stop) return;
    if (!queued) continue;  // a request: applied at the top
    try {
      process(*queued);
    } catch (const std::exception& e) {
      // process() turns every expected failure into a drop; this is the last line of defence.
      drop(*queued, "invalid_frame", std::string("unexpected error: ") + e.what());
    }
  }
}

void KeyframeWorker::process(const QueuedFrame& queued) {
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
      handoff_.markChanged();
      return;
    }
  }
  CameraModel camera;
  if (const std::optional<FrameDefect> defect = checkFrame(frame, camera))
    return drop(queued, defect->reason, defect->message);
  {
    std::lock_guard<std::timed_mutex> lock(state_mutex_);
    if (queued.generation != generation_.load()) return;
    camera_frame_ = normaliseFrameId(frame.image->header.frame_id);
  }
  // The waits for the verdict and the pose hold no lock: services and resets go on meanwhile.
  bool external = false;
  if (verdicts_ && verdicts_->active()) {
    const KeyframeVerdicts::Verdict verdict = verdicts_->wait(stamp);
    if (verdict == KeyframeVerdicts::Verdict::kUnknown && intake_.stopping())
      return drop(queued, kShutdownDrop,
                  "the node stopped before the frame's keyframe verdict came on " +
                      verdicts_->describe());
    if (verdict == KeyframeVerdicts::Verdict::kUnknown)
      return drop(queued, "no_keyframe_verdict",
                  "no stamp on " + verdicts_->describe() + " at or after " + stampText(stamp) +
                      " within " + std::to_string(config_.keyframe_verdict_timeout) +
                      " s (~keyframe_verdict_timeout): the frame's verdict is unknown");
    external = verdict == KeyframeVerdicts::Verdict::kKeyframe;
  }
  const PoseLookup lookup = poses_.lookup(normaliseFrameId(frame.image->header.frame_id), stamp);
  if (!lookup.pose && lookup.reason == "no_pose" && intake_.stopping())
    return drop(queued, kShutdownDrop,
                "the node stopped before the frame's pose came (" + lookup.message + ")");
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
    handoff_.markChanged();
  };
  if (last_stamp_ && !(stamp.toSec() > *last_stamp_))
    return dropLocked("out_of_order_stamp",
                      "stamp " + stampText(stamp) + " is not after the previous frame's");
  core::Frame core_frame;
  core_frame.stamp = stamp.toSec();
  core_frame.image_name = keyframeImageName(core_frame.stamp);
  core_frame.intrinsics = camera.intrinsics;
  // The pose source's history keeps the pose as the source gave it (a later path's corrections
  // are measured against that); the core gets it corrected as the keyframes around it are.
  core_frame.pose = later_corrections_.empty()
                        ? *lookup.pose
                        : core::correctedPose(later_corrections_, core_frame.stamp,
                                              lookup.uncorrected.value_or(*lookup.pose));
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
          images::colourImageOf(rectifiedImage(camera, images::matOf(core_frame.image)));
  } catch (const core::InvalidInput& e) {
    return dropLocked("bad_image", e.what());
  }
  // Feature points use the image alone (as select_views --points features reads no depth).
  if (wanted && frame.depth && config_.point_source != "features") {
    try {
      cv::Mat metres = depthToMetres(*frame.depth, config_.depth_16u_metres_per_unit);
      if (camera.rectify) metres = rectifiedDepth(camera, metres);
      core_frame.depth = images::depthImageOf(metres);
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
  handoff_.markChanged();
  double insertion = -1.0;
  if (result.outcome == core::FrameOutcome::kKeyframe) {
    images_.keyframeAccepted(static_cast<size_t>(result.id), core_frame.image_name, frame.image,
                             camera);
    insertion = result.points_seconds + result.matrix_seconds;
    // Counted before the selection is shared: a reader never sees more keyframes in the
    // selection than in the statistics.
    statistics_.frameOffered(queued.session, stamp, insertion);
    const std::string unlogged = registration_log_.keyframeAdded(result.id, core_frame.stamp);
    if (!unlogged.empty())
      ROS_WARN_STREAM("view_selection: "
                      << unlogged << ": after a restart, revisits of keyframe " << result.id
                      << " and later ones are recognised only where new keyframes are made");
    keyframeInsertedLocked();
    ROS_DEBUG_STREAM("view_selection: keyframe "
                     << result.id << " at " << stampText(stamp) << ": " << result.points
                     << " points, insertion " << 1e3 * insertion << " ms (points "
                     << 1e3 * result.points_seconds << " ms, matrix " << 1e3 * result.matrix_seconds
                     << " ms), " << selector_->matrix().size() << " keyframes");
    handoff_.keyframeInserted(*selector_);  // an autosave every ~autosave_keyframes
    return;
  }
  if (result.covered_by >= 0) statistics_.revisit(queued.session, result.covered_by_registration);
  statistics_.frameOffered(queued.session, stamp, insertion);
}

}  // namespace view_selection::ros_node
