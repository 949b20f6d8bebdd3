#include "view_selection/ros/frame_inputs.h"

#include "view_selection/core/exceptions.h"

#include "view_selection/ros/conversions.h"

#include <cmath>

namespace view_selection::ros_node {

FrameInputs::FrameInputs(const NodeConfig& config, ros::NodeHandle nh, ros::NodeHandle private_nh,
                         KeyframeWorker& worker, InputStatistics& statistics)
    : config_(config), nh_(nh), worker_(worker), statistics_(statistics), it_(nh) {
  if (config_.point_source == "map")
    points_sub_ = nh_.subscribe("points", kMapQueue, &FrameInputs::onMapPoints, this);
  const uint32_t q = static_cast<uint32_t>(config_.queue_size);
  image_sub_.subscribe(it_, "image", q,
                       image_transport::TransportHints("raw", ros::TransportHints(), private_nh));
  image_sub_.registerCallback(&FrameInputs::onRawImage, this);
  info_sub_.subscribe(nh_, "camera_info", q);
  if (config_.use_depth) {
    depth_sub_.subscribe(it_, "depth", q,
                         image_transport::TransportHints("raw", ros::TransportHints(), private_nh,
                                                         "depth_image_transport"));
    sync_depth_ = std::make_unique<message_filters::Synchronizer<SyncDepth>>(
        SyncDepth(q), image_sub_, info_sub_, depth_sub_);
    sync_depth_->registerCallback(&FrameInputs::onFrame, this);
  } else {
    sync_image_ = std::make_unique<message_filters::Synchronizer<SyncImage>>(SyncImage(q),
                                                                             image_sub_, info_sub_);
    sync_image_->registerCallback(&FrameInputs::onImageFrame, this);
  }
  check_timer_ = private_nh.createWallTimer(
      ros::WallDuration(kCheckPeriod), [this](const ros::WallTimerEvent&) { checkUnmatched(); });
}

FrameInputs::~FrameInputs() {
  check_timer_.stop();
  sync_depth_.reset();
  sync_image_.reset();
  image_sub_.unsubscribe();
  depth_sub_.unsubscribe();
  info_sub_.unsubscribe();
  points_sub_.shutdown();
}

void FrameInputs::onFrame(const sensor_msgs::ImageConstPtr& image,
                          const sensor_msgs::CameraInfoConstPtr& info,
                          const sensor_msgs::ImageConstPtr& depth) {
  worker_.push({image, info, depth});  // counts it as received
}

void FrameInputs::onImageFrame(const sensor_msgs::ImageConstPtr& image,
                               const sensor_msgs::CameraInfoConstPtr& info) {
  onFrame(image, info, nullptr);
}

void FrameInputs::checkUnmatched() {
  // Images arrive but never become frames: the synchroniser finds no partner for them.
  if (raw_images_.load() < kUnmatchedWarning || statistics_.counts().frames_received > 0) return;
  ROS_WARN_STREAM("view_selection: "
                  << raw_images_.load() << " images arrived on '" << nh_.resolveName("image")
                  << "' but none was matched with camera_info"
                  << (config_.use_depth ? " and '" + nh_.resolveName("depth") + "'" : std::string())
                  << "; check the remaps"
                  << (config_.use_depth ? " (or set ~use_depth false for images without depth)"
                                        : ""));
}

void FrameInputs::onMapPoints(const sensor_msgs::PointCloud2ConstPtr& cloud) {
  auto reject = [&](const std::string& why) {
    statistics_.dropInput("bad_map",
                          "ignored the map on '" + nh_.resolveName("points") + "': " + why,
                          cloud->header.stamp);
  };
  if (normaliseFrameId(cloud->header.frame_id) != config_.world_frame)
    return reject("the cloud is in frame '" + cloud->header.frame_id + "', not ~world_frame '" +
                  config_.world_frame + "'");
  Eigen::Matrix3Xd points;
  try {
    points = mapPointsFromCloud(*cloud);
  } catch (const core::InvalidInput& e) {
    return reject(e.what());
  }
  try {
    worker_.setMapPoints(std::move(points));
  } catch (const core::InvalidInput& e) {
    reject(e.what());
  }
}

}  // namespace view_selection::ros_node
