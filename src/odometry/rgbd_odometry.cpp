#include "view_selection/odometry/rgbd_odometry.h"

#include "view_selection/core/exceptions.h"

#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd.hpp>

#include <cmath>

namespace view_selection::odometry {

namespace {

constexpr double kPi = 3.14159265358979323846;

double angleDeg(const Eigen::Isometry3d& t) {
  return Eigen::AngleAxisd(t.rotation()).angle() * 180.0 / kPi;
}

}  // namespace

const char* statusName(OdometryResult::Status status) {
  switch (status) {
    case OdometryResult::Status::kInitialised: return "initialised";
    case OdometryResult::Status::kTracked: return "tracked";
    case OdometryResult::Status::kLost: return "lost";
    case OdometryResult::Status::kRestarted: return "restarted";
  }
  return "unknown";
}

void OdometryConfig::validate() const {
  if (method != "rgbd" && method != "icp" && method != "rgbd_icp")
    throw core::InvalidArgument("odometry method must be rgbd, icp or rgbd_icp, not '" + method + "'");
  if (reference != "keyframe" && reference != "frame")
    throw core::InvalidArgument("odometry reference must be keyframe or frame, not '" + reference + "'");
  if (!(keyframe_translation > 0.0) || !(keyframe_rotation_deg > 0.0))
    throw core::InvalidArgument("keyframe_translation and keyframe_rotation_deg must be positive");
  if (!(min_depth >= 0.0) || !(max_depth > min_depth))
    throw core::InvalidArgument("odometry depth range must satisfy 0 <= min_depth < max_depth");
  if (!(max_depth_difference > 0.0)) throw core::InvalidArgument("max_depth_difference must be positive");
  if (!(max_translation > 0.0) || !(max_rotation_deg > 0.0))
    throw core::InvalidArgument("max_translation and max_rotation_deg must be positive");
  if (!(min_valid_depth >= 0.0 && min_valid_depth <= 1.0))
    throw core::InvalidArgument("min_valid_depth must be in [0, 1]");
  if (!(min_contrast >= 0.0)) throw core::InvalidArgument("min_contrast must be >= 0");
  if (restart_after_lost < 1) throw core::InvalidArgument("restart_after_lost must be >= 1");
  if (max_width < 0) throw core::InvalidArgument("max_width must be >= 0 (0: full size)");
}

struct RgbdOdometryTracker::Impl {
  cv::Ptr<cv::rgbd::Odometry> odometry;
  cv::Ptr<cv::rgbd::OdometryFrame> reference;  ///< with its pyramids cached
  Eigen::Isometry3d reference_pose = Eigen::Isometry3d::Identity();  ///< camera-to-odom
  Eigen::Isometry3d last_pose = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d last_motion = Eigen::Isometry3d::Identity();  ///< the last frame in the reference's frame
  Eigen::Isometry3d step = Eigen::Isometry3d::Identity();  ///< the last tracked frame-to-frame motion ...
  double step_seconds = 0.0;                               ///< ... over this time (0: none yet)
  double last_stamp = 0.0;
  core::PinholeIntrinsics intrinsics;
  bool started = false;
  int lost_in_a_row = 0;
};

RgbdOdometryTracker::RgbdOdometryTracker(const OdometryConfig& config)
    : config_(config), impl_(std::make_unique<Impl>()) {
  config_.validate();
}

RgbdOdometryTracker::~RgbdOdometryTracker() = default;

void RgbdOdometryTracker::reset() {
  impl_ = std::make_unique<Impl>();
  counts_ = {};
}

OdometryResult RgbdOdometryTracker::track(double stamp, const cv::Mat& full_image, const cv::Mat& full_depth,
                                          const core::PinholeIntrinsics& full_k) {
  if (full_image.empty() || full_depth.empty() || full_image.size() != full_depth.size())
    throw core::InvalidInput("odometry: image and depth must be non-empty and of one size");
  if (full_depth.type() != CV_32FC1) throw core::InvalidInput("odometry: depth must be CV_32FC1 metres");
  if (full_image.type() != CV_8UC1 && full_image.type() != CV_8UC3)
    throw core::InvalidInput("odometry: the image must be 8-bit grey or BGR");
  if (!(full_k.fx > 0.0 && full_k.fy > 0.0) || !std::isfinite(full_k.cx) || !std::isfinite(full_k.cy))
    throw core::InvalidInput("odometry: unusable intrinsics");
  cv::Mat image = full_image, depth = full_depth;
  core::PinholeIntrinsics k = full_k;
  const int factor = config_.max_width > 0 ? (full_image.cols + config_.max_width - 1) / config_.max_width : 1;
  if (factor > 1) {
    const double f = 1.0 / factor;
    const cv::Size size(full_image.cols / factor, full_image.rows / factor);
    cv::resize(full_image, image, size, 0, 0, cv::INTER_AREA);
    cv::resize(full_depth, depth, size, 0, 0, cv::INTER_NEAREST);  // no depth invented between surfaces
    k.fx *= f;
    k.fy *= f;
    k.cx = (k.cx + 0.5) * f - 0.5;
    k.cy = (k.cy + 0.5) * f - 0.5;
    k.width = size.width;
    k.height = size.height;
  }
  ++counts_.frames;
  Impl& s = *impl_;
  OdometryResult result;
  const auto lost = [&](const std::string& why) {
    ++counts_.lost;
    ++s.lost_in_a_row;
    result.status = OdometryResult::Status::kLost;
    result.reason = why;
    return result;
  };

  cv::Mat grey;
  if (image.type() == CV_8UC3)
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  else
    grey = image.clone();
  cv::Mat d = depth.clone();
  cv::Mat mask = (d > config_.min_depth) & (d < config_.max_depth);  // NaN compares false
  d.setTo(0.0f, ~mask);
  const double valid = static_cast<double>(cv::countNonZero(mask)) / static_cast<double>(mask.total());
  cv::Scalar mean, stddev;
  cv::meanStdDev(grey, mean, stddev);
  if (stddev[0] < config_.min_contrast)
    return lost("a blank image (grey-level deviation " + std::to_string(stddev[0]) + ")");
  if (valid < config_.min_valid_depth)
    return lost("no usable depth (" + std::to_string(100.0 * valid) + "% of the pixels within [" +
                std::to_string(config_.min_depth) + ", " + std::to_string(config_.max_depth) + "] m)");

  const bool new_camera = !s.started || k.fx != s.intrinsics.fx || k.fy != s.intrinsics.fy ||
                          k.cx != s.intrinsics.cx || k.cy != s.intrinsics.cy;
  if (new_camera) {
    const cv::Mat camera = (cv::Mat_<float>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
    const float near = static_cast<float>(config_.min_depth), far = static_cast<float>(config_.max_depth);
    const float diff = static_cast<float>(config_.max_depth_difference);
    if (config_.method == "rgbd") {
      auto o = cv::rgbd::RgbdOdometry::create(camera, near, far, diff);
      o->setMaxTranslation(config_.max_translation);
      o->setMaxRotation(config_.max_rotation_deg);
      s.odometry = o;
    } else if (config_.method == "icp") {
      auto o = cv::rgbd::ICPOdometry::create(camera, near, far, diff);
      o->setMaxTranslation(config_.max_translation);
      o->setMaxRotation(config_.max_rotation_deg);
      s.odometry = o;
    } else {
      auto o = cv::rgbd::RgbdICPOdometry::create(camera, near, far, diff);
      o->setMaxTranslation(config_.max_translation);
      o->setMaxRotation(config_.max_rotation_deg);
      s.odometry = o;
    }
    s.intrinsics = k;
  }
  cv::Ptr<cv::rgbd::OdometryFrame> frame = cv::rgbd::OdometryFrame::create(grey, d, mask);
  const auto makeReference = [&](const Eigen::Isometry3d& pose) {
    s.odometry->prepareFrameCache(frame, cv::rgbd::OdometryFrame::CACHE_ALL);
    s.reference = frame;
    s.reference_pose = pose;
    s.last_pose = pose;
    s.last_motion = Eigen::Isometry3d::Identity();
    s.lost_in_a_row = 0;
    s.last_stamp = stamp;
    ++counts_.keyframes;
    result.pose = pose;
    result.new_keyframe = true;
  };
  if (!s.started) {
    s.started = true;
    makeReference(Eigen::Isometry3d::Identity());
    ++counts_.tracked;
    result.status = OdometryResult::Status::kInitialised;
    return result;
  }
  if (new_camera || s.lost_in_a_row >= config_.restart_after_lost) {
    // The motion while lost (or across a change of camera) is unknown: start again where it was.
    makeReference(s.last_pose);
    s.step_seconds = 0.0;  // the velocity is unknown too
    ++counts_.restarts;
    ++counts_.tracked;
    result.status = OdometryResult::Status::kRestarted;
    result.reason = new_camera ? "the camera's intrinsics changed" : "tracking was lost for too long";
    return result;
  }

  // Rt maps points of the reference frame into the current one: current = Rt * reference. The
  // guess: the last frame moved on by the last step, scaled to the time since (constant velocity).
  Eigen::Isometry3d predicted = s.last_motion;
  if (s.step_seconds > 0.0 && stamp > s.last_stamp) {
    const double f = std::min(4.0, (stamp - s.last_stamp) / s.step_seconds);
    const Eigen::AngleAxisd turn(s.step.linear());
    Eigen::Isometry3d scaled = Eigen::Isometry3d::Identity();
    scaled.linear() = Eigen::AngleAxisd(f * turn.angle(), turn.axis()).toRotationMatrix();
    scaled.translation() = f * s.step.translation();
    predicted = s.last_motion * scaled;
  }
  cv::Mat rt;
  cv::Mat guess;
  cv::eigen2cv(Eigen::Matrix4d(predicted.inverse().matrix()), guess);
  bool ok = false;
  try {
    ok = s.odometry->compute(s.reference, frame, rt, guess);
  } catch (const cv::Exception& e) {
    return lost(std::string("OpenCV's odometry failed: ") + e.what());
  }
  if (!ok || rt.empty())
    return lost("the odometry did not converge (too little texture or depth in common with its reference, or a "
                "motion beyond " + std::to_string(config_.max_translation) + " m / " +
                std::to_string(config_.max_rotation_deg) + " deg)");
  Eigen::Matrix4d m;
  cv::cv2eigen(rt, m);
  if (!m.allFinite()) return lost("the odometry gave a non-finite motion");
  Eigen::Isometry3d current_from_reference(m);
  const Eigen::Isometry3d motion = current_from_reference.inverse();  // the current camera in the reference's frame
  result.pose = s.reference_pose * motion;
  result.status = OdometryResult::Status::kTracked;
  ++counts_.tracked;
  s.lost_in_a_row = 0;
  if (stamp > s.last_stamp) {
    s.step = s.last_pose.inverse() * result.pose;
    s.step_seconds = stamp - s.last_stamp;
  }
  s.last_stamp = stamp;
  s.last_pose = result.pose;
  s.last_motion = motion;
  const bool far = motion.translation().norm() > config_.keyframe_translation ||
                   angleDeg(motion) > config_.keyframe_rotation_deg;
  if (config_.reference == "frame" || far) {
    makeReference(result.pose);
  }
  return result;
}

}  // namespace view_selection::odometry
