#include "view_selection/ros/rgbd_odometry_ros.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/ros/conversions.h"
#include "view_selection/ros/node_config.h"

#include <geometry_msgs/TransformStamped.h>

#include <chrono>

namespace view_selection::ros_node {

namespace {

template <typename T>
T param(const ros::NodeHandle& nh, const std::string& name, const T& fallback) {
  T value = fallback;
  nh.param(name, value, fallback);
  return value;
}

constexpr size_t kMaxWaitingImages = 5;   // beyond, the oldest is decided at once
constexpr size_t kMaxDepths = 30;          // one second at 30 Hz

}  // namespace

RgbdOdometryRosConfig loadRgbdOdometryConfig(const ros::NodeHandle& p) {
  RgbdOdometryRosConfig c;
  odometry::OdometryConfig& o = c.odometry;
  o.method = param(p, "method", o.method);
  o.reference = param(p, "reference", o.reference);
  o.keyframe_translation = param(p, "keyframe_translation", o.keyframe_translation);
  o.keyframe_rotation_deg = param(p, "keyframe_rotation_deg", o.keyframe_rotation_deg);
  o.min_depth = param(p, "min_depth", o.min_depth);
  o.max_depth = param(p, "max_depth", o.max_depth);
  o.max_depth_difference = param(p, "max_depth_difference", o.max_depth_difference);
  o.max_translation = param(p, "max_translation", o.max_translation);
  o.max_rotation_deg = param(p, "max_rotation_deg", o.max_rotation_deg);
  o.min_valid_depth = param(p, "min_valid_depth", o.min_valid_depth);
  o.min_contrast = param(p, "min_contrast", o.min_contrast);
  o.restart_after_lost = param(p, "restart_after_lost", o.restart_after_lost);
  o.max_width = param(p, "max_width", o.max_width);
  o.validate();
  c.odom_frame = normaliseFrameId(param(p, "odom_frame", c.odom_frame));
  c.camera_frame = normaliseFrameId(param(p, "camera_frame", c.camera_frame));
  c.publish_tf = param(p, "publish_tf", c.publish_tf);
  c.max_stamp_difference = param(p, "max_stamp_difference", c.max_stamp_difference);
  c.depth_metres_per_unit = param(p, "depth_metres_per_unit", c.depth_metres_per_unit);
  c.time_jump = param(p, "time_jump", c.time_jump);
  if (c.odom_frame.empty()) throw core::InvalidArgument("~odom_frame must not be empty");
  if (!(c.max_stamp_difference > 0.0)) throw core::InvalidArgument("~max_stamp_difference must be positive [s]");
  if (!(c.depth_metres_per_unit > 0.0)) throw core::InvalidArgument("~depth_metres_per_unit must be positive");
  if (!(c.time_jump > 0.0)) throw core::InvalidArgument("~time_jump must be positive [s]");
  return c;
}

RgbdOdometryRos::RgbdOdometryRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : config_(loadRgbdOdometryConfig(private_nh)),
      nh_(nh),
      private_nh_(private_nh),
      diagnostics_(nh, private_nh),
      tracker_(config_.odometry) {
  odometry_pub_ = private_nh_.advertise<nav_msgs::Odometry>("odometry", 10);
  diagnostics_.setHardwareID("rgbd_odometry");
  diagnostics_.add("tracking", this, &RgbdOdometryRos::diagnose);
  // Wall time: with a bag's /clock the sim time stops when the bag does, and the counts must
  // still be reported after it.
  diagnostics_timer_ =
      nh_.createWallTimer(ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) { diagnostics_.force_update(); });
  thread_ = std::thread(&RgbdOdometryRos::run, this);
  image_sub_ = nh_.subscribe("image", 5, &RgbdOdometryRos::onImage, this);
  depth_sub_ = nh_.subscribe("depth", 10, &RgbdOdometryRos::onDepth, this);
  info_sub_ = nh_.subscribe("camera_info", 5, &RgbdOdometryRos::onInfo, this);
  ROS_INFO("rgbd_odometry: OpenCV RGB-D odometry (%s, against the previous %s), poses in '%s' -> %s; it drifts and "
           "does not close loops",
           config_.odometry.method.c_str(), config_.odometry.reference.c_str(), config_.odom_frame.c_str(),
           config_.camera_frame.empty() ? "the images' frame" : config_.camera_frame.c_str());
}

RgbdOdometryRos::~RgbdOdometryRos() {
  {
    std::lock_guard<std::mutex> guard(lock_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void RgbdOdometryRos::onInfo(const sensor_msgs::CameraInfoConstPtr& msg) {
  std::lock_guard<std::mutex> guard(lock_);
  info_ = msg;
  pair();
}

void RgbdOdometryRos::onDepth(const sensor_msgs::ImageConstPtr& msg) {
  std::lock_guard<std::mutex> guard(lock_);
  if (!depths_.empty() && msg->header.stamp + ros::Duration(config_.time_jump) < depths_.back()->header.stamp)
    depths_.clear();  // a new timeline of this input
  depths_.push_back(msg);
  while (depths_.size() > kMaxDepths) depths_.pop_front();
  pair();
}

void RgbdOdometryRos::onImage(const sensor_msgs::ImageConstPtr& msg) {
  std::lock_guard<std::mutex> guard(lock_);
  ++images_received_;
  if (!newest_.isZero() && msg->header.stamp + ros::Duration(config_.time_jump) < newest_) {
    ROS_WARN("rgbd_odometry: an image %.3f s before the newest: time went back (a bag played again?); starting a "
             "new session at the identity",
             (newest_ - msg->header.stamp).toSec());
    images_.clear();
    has_mail_ = false;
    reset_tracker_ = true;
    ++sessions_;
    newest_ = msg->header.stamp;
  }
  newest_ = std::max(newest_, msg->header.stamp);
  images_.push_back(msg);
  pair();
}

void RgbdOdometryRos::pair() {
  while (!images_.empty()) {
    const sensor_msgs::ImageConstPtr image = images_.front();
    const ros::Time t = image->header.stamp;
    const bool later_depth = !depths_.empty() && depths_.back()->header.stamp >= t;
    if (!later_depth && images_.size() <= kMaxWaitingImages) return;  // its nearest depth may still come
    if (!info_ && images_.size() <= kMaxWaitingImages) return;
    images_.pop_front();
    sensor_msgs::ImageConstPtr best;
    for (const auto& d : depths_)
      if (!best || std::abs((d->header.stamp - t).toSec()) < std::abs((best->header.stamp - t).toSec())) best = d;
    if (!info_ || !best || std::abs((best->header.stamp - t).toSec()) > config_.max_stamp_difference) {
      ++unpaired_;
      ROS_WARN_THROTTLE(5.0, "rgbd_odometry: image at %.3f has %s: not tracked (%llu so far)", t.toSec(),
                        !info_ ? "no camera_info yet"
                               : "no depth within ~max_stamp_difference",
                        static_cast<unsigned long long>(unpaired_));
      continue;
    }
    ++paired_;
    if (has_mail_) ++skipped_;  // the tracker is behind: the waiting frame is dropped for the newer
    mailbox_ = {image, best, info_};
    has_mail_ = true;
    wake_.notify_one();
  }
}

void RgbdOdometryRos::run() {
  while (true) {
    Pending frame;
    bool reset = false;
    {
      std::unique_lock<std::mutex> guard(lock_);
      wake_.wait(guard, [&] { return stopping_ || has_mail_; });
      if (stopping_) return;
      frame = mailbox_;
      has_mail_ = false;
      reset = reset_tracker_;
      reset_tracker_ = false;
    }
    if (reset) tracker_.reset();
    track(frame);
  }
}

void RgbdOdometryRos::track(const Pending& frame) {
  const ros::Time stamp = frame.image->header.stamp;
  odometry::OdometryResult result;
  const auto start = std::chrono::steady_clock::now();
  try {
    checkImageMessage(*frame.image, "image");
    checkImageMessage(*frame.depth, "depth");
    checkDepthEncoding(*frame.depth);
    const cv::Mat image = imageForCore(frame.image);
    const cv::Mat depth = depthToMetres(*frame.depth, config_.depth_metres_per_unit);
    const core::PinholeIntrinsics k = intrinsicsFromCameraInfo(*frame.info);
    if (image.cols != k.width || image.rows != k.height)
      throw core::InvalidInput("the image is " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                               ", camera_info says " + std::to_string(k.width) + "x" + std::to_string(k.height));
    if (depth.size() != image.size())
      throw core::InvalidInput("depth and image differ in size (registered depth is needed)");
    result = tracker_.track(stamp.toSec(), image, depth, k);
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> guard(lock_);
    ++bad_input_;
    last_error_ = e.what();
    ROS_ERROR_THROTTLE(5.0, "rgbd_odometry: frame at %.3f not used: %s (%llu so far)", stamp.toSec(), e.what(),
                       static_cast<unsigned long long>(bad_input_));
    return;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  uint64_t lost = 0;
  {
    std::lock_guard<std::mutex> guard(lock_);
    seconds_ += seconds;
    if (result.status == odometry::OdometryResult::Status::kLost) {
      ++lost_;
      ++lost_in_period_;
      last_lost_ = result.reason;
    } else {
      ++tracked_;
      if (result.status == odometry::OdometryResult::Status::kRestarted) ++restarts_;
    }
    lost = lost_;
  }
  if (result.status == odometry::OdometryResult::Status::kLost) {
    ROS_WARN_THROTTLE(2.0, "rgbd_odometry: tracking lost at %.3f: %s (no pose for it; %llu lost so far)",
                      stamp.toSec(), result.reason.c_str(), static_cast<unsigned long long>(lost));
    return;
  }
  if (result.status == odometry::OdometryResult::Status::kRestarted)
    ROS_WARN("rgbd_odometry: restarted at %.3f from its last pose (%s): the motion while lost is missing",
             stamp.toSec(), result.reason.c_str());
  const std::string child =
      config_.camera_frame.empty() ? normaliseFrameId(frame.image->header.frame_id) : config_.camera_frame;
  core::CameraPose pose;
  pose.position = result.pose.translation();
  pose.orientation = Eigen::Quaterniond(result.pose.linear()).normalized();
  nav_msgs::Odometry odom;
  odom.header.stamp = stamp;
  odom.header.frame_id = config_.odom_frame;
  odom.child_frame_id = child;
  odom.pose.pose = poseToMsg(pose);
  // Covariances are not estimated: all zero (the twist is not given either).
  odometry_pub_.publish(odom);
  if (config_.publish_tf && !child.empty()) {
    geometry_msgs::TransformStamped t;
    t.header = odom.header;
    t.child_frame_id = child;
    t.transform = transformToMsg(pose);
    tf_.sendTransform(t);
  }
}

void RgbdOdometryRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  std::lock_guard<std::mutex> guard(lock_);
  if (tracked_ == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no frame tracked yet");
  else if (lost_in_period_ > 0)
    status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN, "tracking lost on %llu frames since the last report: %s",
                    static_cast<unsigned long long>(lost_in_period_), last_lost_.c_str());
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "tracking");
  lost_in_period_ = 0;
  status.add("images", images_received_);
  status.add("paired with depth", paired_);
  status.add("without depth or camera_info", unpaired_);
  status.add("skipped (tracker busy)", skipped_);
  status.add("bad input", bad_input_);
  status.add("tracked", tracked_);
  status.add("lost", lost_);
  status.add("restarts", restarts_);
  status.add("sessions", sessions_);
  status.add("last lost", last_lost_);
  status.add("last error", last_error_);
  status.add("mean tracking time [ms]", tracked_ + lost_ ? 1000.0 * seconds_ / static_cast<double>(tracked_ + lost_) : 0.0);
}

}  // namespace view_selection::ros_node
