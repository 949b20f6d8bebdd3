// The node's inputs: `image`, `camera_info` and (with ~use_depth) `depth`, through image_transport
// and synchronised by message_filters' ApproximateTime; and, for the "map" point source, map
// points on `points`. Frames go to the worker; bad clouds are counted as drops.
#pragma once

#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_worker.h"
#include "view_selection/ros/node_config.h"

#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>

#include <atomic>
#include <memory>

namespace view_selection::ros_node {

class FrameInputs {
 public:
  /// Subscribes (relative names on `nh`, transports from `private_nh`'s ~image_transport and
  /// ~depth_image_transport). Throws what image_transport throws for an unknown transport.
  FrameInputs(const NodeConfig& config, ros::NodeHandle nh, ros::NodeHandle private_nh,
              KeyframeWorker& worker, InputStatistics& statistics);
  ~FrameInputs();

 private:
  static constexpr uint32_t kMapQueue = 2;      ///< map clouds: each replaces the last, keep few
  static constexpr double kCheckPeriod = 10.0;  ///< [s, wall] between checks for unmatched images
  static constexpr uint64_t kUnmatchedWarning = 30;  ///< images without a frame before warning

  void onFrame(const sensor_msgs::ImageConstPtr& image, const sensor_msgs::CameraInfoConstPtr& info,
               const sensor_msgs::ImageConstPtr& depth);
  void onImageFrame(const sensor_msgs::ImageConstPtr& image,
                    const sensor_msgs::CameraInfoConstPtr& info);
  void onRawImage(const sensor_msgs::ImageConstPtr&) { ++raw_images_; }
  void onMapPoints(const sensor_msgs::PointCloud2ConstPtr& cloud);
  void checkUnmatched();

  const NodeConfig& config_;
  ros::NodeHandle nh_;
  KeyframeWorker& worker_;
  InputStatistics& statistics_;
  std::atomic<uint64_t> raw_images_{0};

  image_transport::ImageTransport it_;
  image_transport::SubscriberFilter image_sub_, depth_sub_;
  message_filters::Subscriber<sensor_msgs::CameraInfo> info_sub_;
  using SyncDepth =
      message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo,
                                                      sensor_msgs::Image>;
  using SyncImage =
      message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo>;
  std::unique_ptr<message_filters::Synchronizer<SyncDepth>> sync_depth_;
  std::unique_ptr<message_filters::Synchronizer<SyncImage>> sync_image_;
  ros::Subscriber points_sub_;
  ros::WallTimer check_timer_;
};

}  // namespace view_selection::ros_node
