#include "view_selection/ros/view_selection_ros.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/selection_io.h"
#include "view_selection/core/selection_plot.h"
#include "view_selection/ros/conversions.h"
#include "view_selection/ros/markers.h"

#include "view_selection/core/map_point_source.h"

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <opencv2/imgcodecs.hpp>
#include <sensor_msgs/image_encodings.h>
#include <tf2/exceptions.h>
#include <visualization_msgs/MarkerArray.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <sstream>

namespace fs = std::filesystem;

namespace view_selection {
namespace ros_node {

namespace {

constexpr double kLogThrottlePeriod = 5.0;  // [s, wall] per drop reason

std::string stampText(const ros::Time& t) {
  std::ostringstream s;
  s.precision(6);
  s << std::fixed << t.toSec();
  return s.str();
}

}  // namespace

ViewSelectionRos::ViewSelectionRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh), pnh_(private_nh), config_(loadNodeConfig(private_nh)), it_(nh) {
  selector_ = std::make_unique<ViewSelector>(config_.selector,
                                             makePointSource(config_.point_source, config_.point_params));
  selection_ = selector_->select();
  started_ = ros::WallTime::now();

  selection_pub_ = pnh_.advertise<view_selection::ViewSelection>("selection", 1, true);
  markers_pub_ = pnh_.advertise<visualization_msgs::MarkerArray>("markers", 1, true);
  statistics_pub_ = pnh_.advertise<view_selection::InputStatistics>("statistics", 1, true);
  next_views_srv_ = pnh_.advertiseService("get_next_views", &ViewSelectionRos::getNextViews, this);
  selection_srv_ = pnh_.advertiseService("get_selection", &ViewSelectionRos::getSelection, this);
  export_srv_ = pnh_.advertiseService("export", &ViewSelectionRos::exportSelection, this);
  reset_srv_ = pnh_.advertiseService("reset", &ViewSelectionRos::reset, this);

  if (config_.pose_source == PoseSource::kTf) {
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
    // Its own spinner thread: poses keep arriving while the worker waits for one.
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh_, true);
  } else {
    pose_sub_ = nh_.subscribe("pose", 100, &ViewSelectionRos::onPose, this);
  }

  if (config_.point_source == "map")
    points_sub_ = nh_.subscribe("points", 2, &ViewSelectionRos::onMapPoints, this);

  worker_ = std::thread([this] { workerLoop(); });

  const uint32_t q = static_cast<uint32_t>(config_.queue_size);
  image_sub_.subscribe(it_, "image", q, image_transport::TransportHints("raw", ros::TransportHints(), pnh_));
  image_sub_.registerCallback(&ViewSelectionRos::onRawImage, this);
  info_sub_.subscribe(nh_, "camera_info", q);
  if (config_.use_depth) {
    depth_sub_.subscribe(it_, "depth", q,
                         image_transport::TransportHints("raw", ros::TransportHints(), pnh_, "depth_image_transport"));
    sync_depth_ = std::make_unique<message_filters::Synchronizer<SyncDepth>>(SyncDepth(q), image_sub_, info_sub_,
                                                                              depth_sub_);
    sync_depth_->registerCallback(&ViewSelectionRos::onFrame, this);
  } else {
    sync_image_ = std::make_unique<message_filters::Synchronizer<SyncImage>>(SyncImage(q), image_sub_, info_sub_);
    sync_image_->registerCallback(&ViewSelectionRos::onImageFrame, this);
  }

  publishSelection();
  publishStatistics();
  const double period = std::max(config_.publish_period, 0.02);
  publish_timer_ = pnh_.createWallTimer(ros::WallDuration(period), &ViewSelectionRos::onPublishTimer, this);

  ROS_INFO_STREAM("view_selection_node: " << (config_.use_depth ? "image + camera_info + depth" : "image + camera_info")
                  << " from '" << nh_.resolveName("image") << "', poses from "
                  << (config_.pose_source == PoseSource::kTf
                          ? "tf (" + config_.world_frame + " <- " +
                                (config_.camera_frame.empty() ? "image frame_id" : config_.camera_frame) + ")"
                          : "'" + nh_.resolveName("pose") + "'")
                  << ", points from " << config_.point_source
                  << (config_.point_source == "map" ? " ('" + nh_.resolveName("points") + "')" : std::string())
                  << ", keyframes " << toString(config_.selector.keyframes.mode) << ", k "
                  << config_.selector.selection.k << ", completion " << toString(config_.selector.selection.completion));
}

ViewSelectionRos::~ViewSelectionRos() {
  publish_timer_.stop();
  sync_depth_.reset();
  sync_image_.reset();
  image_sub_.unsubscribe();
  depth_sub_.unsubscribe();
  info_sub_.unsubscribe();
  pose_sub_.shutdown();
  points_sub_.shutdown();
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    stopping_ = true;
  }
  queue_cv_.notify_all();
  pose_cv_.notify_all();
  if (worker_.joinable()) worker_.join();
}

// ---------------------------------------------------------------------------------------------
// Input

void ViewSelectionRos::onRawImage(const sensor_msgs::ImageConstPtr&) { ++raw_images_; }

void ViewSelectionRos::onFrame(const sensor_msgs::ImageConstPtr& image, const sensor_msgs::CameraInfoConstPtr& info,
                               const sensor_msgs::ImageConstPtr& depth) {
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.frames_received;
    ++stats_version_;
  }
  std::optional<PendingFrame> overflow;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    if (stopping_) return;
    if (queue_.size() >= static_cast<size_t>(config_.max_pending_frames)) {
      overflow = queue_.front();
      queue_.pop_front();
    }
    queue_.push_back({image, info, depth});
  }
  queue_cv_.notify_one();
  if (overflow)
    drop("worker_behind",
         "the worker is " + std::to_string(config_.max_pending_frames) +
             " frames behind (~max_pending_frames); dropped the oldest waiting frame",
         overflow->image->header.stamp);
}

void ViewSelectionRos::onImageFrame(const sensor_msgs::ImageConstPtr& image,
                                    const sensor_msgs::CameraInfoConstPtr& info) {
  onFrame(image, info, nullptr);
}

void ViewSelectionRos::onPose(const geometry_msgs::PoseStampedConstPtr& pose) {
  {
    std::lock_guard<std::mutex> lock(pose_mutex_);
    auto at = std::upper_bound(poses_.begin(), poses_.end(), pose->header.stamp,
                               [](const ros::Time& t, const geometry_msgs::PoseStampedConstPtr& p) {
                                 return t < p->header.stamp;
                               });
    poses_.insert(at, pose);
    // Keep 30 s of poses (and at most 10000): frames older than that are long dropped.
    const ros::Time newest = poses_.back()->header.stamp;
    while (poses_.size() > 10000 ||
           (poses_.size() > 1 && newest.toSec() - poses_.front()->header.stamp.toSec() > 30.0))
      poses_.pop_front();
  }
  pose_cv_.notify_all();
}

void ViewSelectionRos::onMapPoints(const sensor_msgs::PointCloud2ConstPtr& cloud) {
  const std::string frame = normaliseFrameId(cloud->header.frame_id);
  auto reject = [&](const std::string& why) {
    ROS_WARN_STREAM_THROTTLE(5.0, "view_selection: ignored the map on '" << nh_.resolveName("points") << "' at "
                                                                         << stampText(cloud->header.stamp) << ": "
                                                                         << why);
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.dropped["bad_map"];
    stats_.last_error = "bad_map: " + why;
    stats_.last_error_stamp = cloud->header.stamp;
    ++stats_version_;
  };
  if (frame != config_.world_frame)
    return reject("the cloud is in frame '" + cloud->header.frame_id + "', not ~world_frame '" + config_.world_frame +
                  "'");
  const size_t n = static_cast<size_t>(cloud->width) * cloud->height;
  if (cloud->data.size() < static_cast<size_t>(cloud->row_step) * cloud->height ||
      static_cast<size_t>(cloud->point_step) * cloud->width > cloud->row_step)
    return reject("the cloud's data is shorter than its width, height and steps say");
  Eigen::Matrix3Xd points(3, static_cast<Eigen::Index>(n));
  Eigen::Index kept = 0;
  try {
    sensor_msgs::PointCloud2ConstIterator<float> x(*cloud, "x"), y(*cloud, "y"), z(*cloud, "z");
    for (size_t i = 0; i < n; ++i, ++x, ++y, ++z) {
      if (!std::isfinite(*x) || !std::isfinite(*y) || !std::isfinite(*z)) continue;  // organised clouds pad with NaN
      points.col(kept++) = Eigen::Vector3d(*x, *y, *z);
    }
  } catch (const std::exception& e) {
    return reject(std::string("the cloud has no float32 x, y, z fields (") + e.what() + ")");
  }
  points.conservativeResize(3, kept);
  std::lock_guard<std::mutex> lock(state_mutex_);
  auto* map = dynamic_cast<MapPointSource*>(&selector_->pointSource());
  if (!map) return;
  try {
    map->setMapPoints(std::move(points));
    const std::vector<ViewId> rows = selector_->applyPointUpdates();
    if (!rows.empty()) {
      selection_ = selector_->select();
      ++version_;
    }
    ROS_DEBUG_STREAM("view_selection: map of " << kept << " points, " << rows.size() << " keyframe rows recomputed");
  } catch (const InvalidInput& e) {
    reject(e.what());
  }
}

void ViewSelectionRos::workerLoop() {
  while (true) {
    PendingFrame frame;
    {
      std::unique_lock<std::mutex> lock(queue_mutex_);
      queue_cv_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      frame = std::move(queue_.front());
      queue_.pop_front();
    }
    try {
      process(frame);
    } catch (const std::exception& e) {
      // process() turns every expected failure into a drop; this is the last line of defence.
      drop("invalid_frame", std::string("unexpected error: ") + e.what(), frame.image->header.stamp);
    }
  }
}

void ViewSelectionRos::drop(const std::string& reason, const std::string& message, const ros::Time& stamp) {
  uint64_t suppressed = 0;
  bool log = false;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.dropped[reason];
    stats_.last_error = reason + ": " + message;
    stats_.last_error_stamp = stamp;
    ++stats_version_;
    LogThrottle& t = log_throttle_[reason];
    const ros::WallTime now = ros::WallTime::now();
    if (t.last.isZero() || (now - t.last).toSec() >= kLogThrottlePeriod) {
      log = true;
      suppressed = t.suppressed;
      t.suppressed = 0;
      t.last = now;
    } else {
      ++t.suppressed;
    }
  }
  if (log)
    ROS_WARN_STREAM("view_selection: dropped frame at " << stampText(stamp) << " (" << reason << "): " << message
                    << (suppressed ? " [" + std::to_string(suppressed) + " more such drops not logged]" : ""));
}

std::optional<CameraPose> ViewSelectionRos::findPose(const PendingFrame& frame, std::string& reason,
                                                     std::string& message) {
  const ros::Time stamp = frame.image->header.stamp;
  if (config_.pose_source == PoseSource::kTopic) return findPoseTopic(stamp, reason, message);
  const std::string camera =
      config_.camera_frame.empty() ? normaliseFrameId(frame.image->header.frame_id) : config_.camera_frame;
  if (camera.empty()) {
    reason = "no_pose";
    message = "the image has no frame_id and ~camera_frame is not set, so there is no frame to look up";
    return std::nullopt;
  }
  return findPoseTf(camera, stamp, reason, message);
}

std::optional<CameraPose> ViewSelectionRos::findPoseTf(const std::string& camera, const ros::Time& stamp,
                                                       std::string& reason, std::string& message) {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(config_.pose_timeout);
  std::string error;
  while (true) {
    error.clear();
    if (tf_buffer_->canTransform(config_.world_frame, camera, stamp, &error)) break;
    if (stopping_) break;
    if (ros::WallTime::now() >= deadline || !ros::ok()) {
      reason = "no_pose";
      message = "no transform " + config_.world_frame + " <- " + camera + " at " + stampText(stamp) + " within " +
                std::to_string(config_.pose_timeout).substr(0, 5) + " s (~pose_timeout): " + error;
      return std::nullopt;
    }
    ros::WallDuration(0.002).sleep();
  }
  try {
    const geometry_msgs::TransformStamped t = tf_buffer_->lookupTransform(config_.world_frame, camera, stamp);
    return poseFromTransform(t.transform);
  } catch (const tf2::TransformException& e) {
    reason = "no_pose";
    message = "no transform " + config_.world_frame + " <- " + camera + " at " + stampText(stamp) + ": " + e.what();
    return std::nullopt;
  }
}

std::optional<CameraPose> ViewSelectionRos::findPoseTopic(const ros::Time& stamp, std::string& reason,
                                                          std::string& message) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(config_.pose_timeout);
  std::unique_lock<std::mutex> lock(pose_mutex_);
  // Wait until a pose at or after the stamp is there (or the timeout), then take the nearest.
  pose_cv_.wait_until(lock, deadline, [&] {
    if (stopping_) return true;
    return !poses_.empty() && poses_.back()->header.stamp >= stamp;
  });
  geometry_msgs::PoseStampedConstPtr best;
  double best_dt = 0.0;
  for (const auto& p : poses_) {
    const double dt = std::abs((p->header.stamp - stamp).toSec());
    if (!best || dt < best_dt) {
      best = p;
      best_dt = dt;
    }
  }
  if (!best || best_dt > config_.pose_max_time_difference) {
    reason = "no_pose";
    message = "no pose on '" + nh_.resolveName("pose") + "' within " +
              std::to_string(config_.pose_max_time_difference).substr(0, 5) + " s of " + stampText(stamp) +
              " (~pose_max_time_difference) after waiting " + std::to_string(config_.pose_timeout).substr(0, 5) +
              " s (~pose_timeout)";
    return std::nullopt;
  }
  const std::string frame = normaliseFrameId(best->header.frame_id);
  if (frame != config_.world_frame) {
    reason = "bad_pose";
    message = "the pose is in frame '" + best->header.frame_id + "', not ~world_frame '" + config_.world_frame + "'";
    return std::nullopt;
  }
  return poseFromMsg(best->pose);
}

void ViewSelectionRos::process(const PendingFrame& frame) {
  const sensor_msgs::Image& image = *frame.image;
  const ros::Time stamp = image.header.stamp;
  PinholeIntrinsics intrinsics;
  try {
    checkImageMessage(image, "image");
  } catch (const InvalidInput& e) {
    return drop("bad_image", e.what(), stamp);
  }
  if (frame.depth) {
    try {
      checkImageMessage(*frame.depth, "depth");
      checkDepthEncoding(*frame.depth);
    } catch (const InvalidInput& e) {
      return drop("bad_depth", e.what(), stamp);
    }
  }
  try {
    intrinsics = intrinsicsFromCameraInfo(*frame.info);
  } catch (const InvalidInput& e) {
    return drop("bad_camera_info", e.what(), stamp);
  }
  if (image.width != frame.info->width || image.height != frame.info->height) {
    std::ostringstream s;
    s << "image is " << image.width << "x" << image.height << " but camera_info says " << frame.info->width << "x"
      << frame.info->height;
    return drop("bad_camera_info", s.str(), stamp);
  }
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    if (last_stamp_ && !(stamp.toSec() > *last_stamp_)) {
      const bool duplicate = stamp.toSec() == *last_stamp_;
      std::ostringstream s;
      s << "stamp " << stampText(stamp) << " is " << (duplicate ? "the same as" : "before") << " the previous frame's "
        << stampText(ros::Time(*last_stamp_));
      return drop(duplicate ? "duplicate_stamp" : "out_of_order_stamp", s.str(), stamp);
    }
  }
  std::string reason, message;
  const std::optional<CameraPose> pose = findPose(frame, reason, message);
  if (!pose) return drop(reason, message, stamp);
  if (!pose->isValid()) return drop("bad_pose", "the camera pose is not finite or its quaternion is not unit length", stamp);

  std::lock_guard<std::mutex> lock(state_mutex_);
  // Checked again: a reset or another frame may have come in while the pose was looked up.
  if (last_stamp_ && !(stamp.toSec() > *last_stamp_))
    return drop("out_of_order_stamp", "stamp " + stampText(stamp) + " is not after the previous frame's", stamp);
  Frame core;
  core.stamp = stamp.toSec();
  core.image_name = keyframeImageName(core.stamp);
  core.intrinsics = intrinsics;
  core.pose = *pose;
  // Normalised here as the TUM reader normalises groundtruth.txt, so that for the same frames the
  // point source sees bit-identical rotations and the matrix equals select_views' exactly.
  core.pose.orientation.normalize();
  // As select_views does: only frames the policy will take get their depth converted.
  const bool wanted = selector_->wantsFrame(*pose);
  try {
    core.image = wanted ? imageForCore(frame.image) : imageView(image);
  } catch (const InvalidInput& e) {
    return drop("bad_image", e.what(), stamp);
  }
  // Feature points use the image alone (as select_views --points features reads no depth).
  if (wanted && frame.depth && config_.point_source != "features") {
    try {
      core.depth_m = depthToMetres(*frame.depth, config_.depth_16u_metres_per_unit);
    } catch (const InvalidInput& e) {
      return drop("bad_depth", e.what(), stamp);
    }
  }
  FrameResult result;
  try {
    result = selector_->addFrame(core);
  } catch (const InvalidInput& e) {
    return drop("invalid_frame", e.what(), stamp);
  }
  last_stamp_ = core.stamp;
  const size_t keyframes = selector_->matrix().size();
  if (result.outcome == FrameOutcome::kKeyframe) {
    if (config_.save_keyframe_images) images_.push_back(frame.image);
    selection_ = selector_->select();
    ++version_;
    ROS_DEBUG_STREAM("view_selection: keyframe " << result.id << " at " << stampText(stamp) << ": " << result.points
                     << " points, insertion " << 1e3 * (result.points_seconds + result.matrix_seconds) << " ms (points "
                     << 1e3 * result.points_seconds << " ms, matrix " << 1e3 * result.matrix_seconds << " ms), "
                     << keyframes << " keyframes");
  }
  std::lock_guard<std::mutex> stats_lock(stats_mutex_);
  ++stats_.frames_offered;
  if (result.outcome == FrameOutcome::kKeyframe) {
    stats_.last_insertion_seconds = result.points_seconds + result.matrix_seconds;
    stats_.max_insertion_seconds = std::max(stats_.max_insertion_seconds, stats_.last_insertion_seconds);
  }
  ++stats_version_;
}

// ---------------------------------------------------------------------------------------------
// Output

void ViewSelectionRos::onPublishTimer(const ros::WallTimerEvent&) {
  uint64_t version;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    version = version_;
  }
  if (version != published_version_) publishSelection();
  uint64_t stats_version;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_version = stats_version_;
  }
  if (stats_version != published_stats_version_) publishStatistics();
  // Images arrive but never become frames: the synchroniser finds no partner for them.
  const uint64_t raw = raw_images_.load();
  uint64_t received;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    received = stats_.frames_received;
  }
  if (raw >= 30 && received == 0)
    ROS_WARN_THROTTLE(10.0, "view_selection: %lu images arrived on '%s' but none was matched with camera_info%s; "
                            "check the remaps%s",
                      static_cast<unsigned long>(raw), nh_.resolveName("image").c_str(),
                      config_.use_depth ? (" and '" + nh_.resolveName("depth") + "'").c_str() : "",
                      config_.use_depth ? " (or set ~use_depth false for images without depth)" : "");
}

void ViewSelectionRos::publishSelection() {
  view_selection::ViewSelection msg;
  visualization_msgs::MarkerArray markers;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    msg = selectionToMsg(selector_->matrix(), selection_, config_.selector.selection, config_.world_frame);
    markers = selectionMarkers(selector_->matrix(), selection_, config_.world_frame, config_.marker_scale);
    published_version_ = version_;
  }
  selection_pub_.publish(msg);
  markers_pub_.publish(markers);
}

void ViewSelectionRos::publishStatistics() {
  view_selection::InputStatistics msg;
  msg.header.stamp = ros::Time(ros::WallTime::now().toSec());
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    msg.keyframes = static_cast<uint32_t>(selector_->matrix().size());
  }
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    msg.frames_received = stats_.frames_received;
    msg.frames_offered = stats_.frames_offered;
    for (const auto& [reason, count] : stats_.dropped) {
      msg.drop_reasons.push_back(reason);
      msg.drop_counts.push_back(count);
      msg.frames_dropped += count;
    }
    msg.last_error = stats_.last_error;
    msg.last_error_stamp = stats_.last_error_stamp;
    msg.last_insertion_seconds = stats_.last_insertion_seconds;
    msg.max_insertion_seconds = stats_.max_insertion_seconds;
    published_stats_version_ = stats_version_;
  }
  statistics_pub_.publish(msg);
}

// ---------------------------------------------------------------------------------------------
// Services

bool ViewSelectionRos::getNextViews(view_selection::GetNextViews::Request& req,
                                    view_selection::GetNextViews::Response& res) {
  std::lock_guard<std::mutex> lock(state_mutex_);
  const size_t n = selector_->matrix().size();
  if (req.view < 0 || static_cast<size_t>(req.view) >= n) {
    res.success = false;
    res.message = "view " + std::to_string(req.view) + " is unknown: " +
                  (n == 0 ? std::string("there are no keyframes yet")
                          : "keyframe ids are 0.." + std::to_string(n - 1));
    return true;
  }
  const auto& sets = req.after_completion ? selection_.final_next_views : selection_.next_views;
  for (const ViewId j : sets[static_cast<size_t>(req.view)]) {
    res.next_views.push_back(j);
    res.error_resistance.push_back(selector_->matrix().at(req.view, j));
  }
  res.success = true;
  res.message = std::to_string(res.next_views.size()) + " next views of view " + std::to_string(req.view) +
                (req.after_completion ? " after completion" : "") + " (" + std::to_string(n) + " keyframes)";
  return true;
}

bool ViewSelectionRos::getSelection(view_selection::GetSelection::Request&,
                                    view_selection::GetSelection::Response& res) {
  std::lock_guard<std::mutex> lock(state_mutex_);
  res.selection = selectionToMsg(selector_->matrix(), selection_, config_.selector.selection, config_.world_frame);
  res.success = true;
  res.message = std::to_string(res.selection.keyframes.size()) + " keyframes, " +
                std::to_string(res.selection.pairs.size()) + " pairs" +
                (res.selection.keyframes.empty() ? " (no keyframes yet)" : "");
  return true;
}

bool ViewSelectionRos::exportSelection(view_selection::Export::Request& req, view_selection::Export::Response& res) {
  res.success = false;
  if (req.directory.empty()) {
    res.message = "directory is empty: give the folder to write selection.json and pairs.txt into";
    return true;
  }
  // A copy of the state under the lock, written outside it: the worker keeps inserting.
  std::unique_ptr<ErrorResistanceMatrix> matrix;
  Selection selection;
  nlohmann::json params;
  std::vector<sensor_msgs::ImageConstPtr> images;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    matrix = std::make_unique<ErrorResistanceMatrix>(selector_->matrix());
    selection = selection_;
    params = selector_->params();
    images = images_;
  }
  try {
    const fs::path dir(req.directory);
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec || !fs::is_directory(dir))
      throw IoError("cannot create folder '" + req.directory + "': " + (ec ? ec.message() : "not a folder"));
    params["source"] = "view_selection_node";
    params["world_frame"] = config_.world_frame;
    params["image_path"] = config_.save_keyframe_images ? "." : "";
    std::vector<std::string> names;
    for (size_t i = 0; i < matrix->size(); ++i) names.push_back(matrix->keyframe(static_cast<ViewId>(i)).image_name);
    res.selection_json = (dir / "selection.json").string();
    res.pairs_txt = (dir / "pairs.txt").string();
    writeSelectionJson(res.selection_json, *matrix, selection, params, false);
    writePairsTxt(res.pairs_txt, names, selection.pairs);
    writeSelectionPlot((dir / "selection.png").string(), *matrix, selection,
                       "view_selection_node, k = " + std::to_string(config_.selector.selection.k) +
                           ", completion: " + toString(config_.selector.selection.completion));
    res.images_written = 0;
    for (size_t i = 0; i < images.size() && i < names.size(); ++i) {
      const fs::path path = dir / names[i];
      fs::create_directories(path.parent_path(), ec);
      cv::Mat bgr;
      try {
        bgr = imageForCore(images[i]);
      } catch (const InvalidInput& e) {
        throw IoError("keyframe " + std::to_string(i) + " image: " + e.what());
      }
      if (!cv::imwrite(path.string(), bgr)) throw IoError("cannot write '" + path.string() + "'");
      ++res.images_written;
    }
    res.success = true;
    res.message = "wrote " + std::to_string(matrix->size()) + " keyframes, " + std::to_string(selection.pairs.size()) +
                  " pairs" +
                  (config_.save_keyframe_images ? ", " + std::to_string(res.images_written) + " images"
                                                : " (no images: ~save_keyframe_images is false)") +
                  " to " + dir.string();
  } catch (const std::exception& e) {
    res.success = false;
    res.message = std::string("export failed: ") + e.what();
  }
  return true;
}

bool ViewSelectionRos::reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  size_t forgotten = 0;
  {
    std::lock_guard<std::mutex> queue_lock(queue_mutex_);
    queue_.clear();
  }
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    forgotten = selector_->matrix().size();
    selector_->reset();
    selection_ = selector_->select();
    images_.clear();
    last_stamp_.reset();
    ++version_;
    ++generation_;
  }
  {
    std::lock_guard<std::mutex> lock(pose_mutex_);
    poses_.clear();
  }
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_ = Statistics{};
    ++stats_version_;
  }
  res.success = true;
  res.message = "forgot " + std::to_string(forgotten) + " keyframes and the input statistics";
  return true;
}

}  // namespace ros_node
}  // namespace view_selection
