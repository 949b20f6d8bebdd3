// The ROS layer over view_selection::ViewSelector, shared by view_selection_node and the
// view_selection/ViewSelectionNodelet. It converts messages, finds poses, and hands frames to
// the core on one worker thread; services read under the same mutex, so they always see a whole
// number of keyframes.
#pragma once

#include "view_selection/ros/messages.h"  // first: see there why

#include "view_selection/core/view_selector.h"
#include "view_selection/ros/node_config.h"

#include <geometry_msgs/PoseStamped.h>
#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace view_selection {
namespace ros_node {

class ViewSelectionRos {
 public:
  /// Reads the ~parameters (throws InvalidArgument naming a bad one), subscribes to the relative
  /// topics on `nh`, advertises outputs and services on `private_nh` and starts the worker.
  ViewSelectionRos(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~ViewSelectionRos();
  ViewSelectionRos(const ViewSelectionRos&) = delete;
  ViewSelectionRos& operator=(const ViewSelectionRos&) = delete;

 private:
  struct PendingFrame {
    sensor_msgs::ImageConstPtr image;
    sensor_msgs::CameraInfoConstPtr info;
    sensor_msgs::ImageConstPtr depth;  // null without depth
  };
  struct Statistics {
    uint64_t frames_received = 0;
    uint64_t frames_offered = 0;
    std::map<std::string, uint64_t> dropped;
    std::string last_error;
    ros::Time last_error_stamp;
    double last_insertion_seconds = 0.0;
    double max_insertion_seconds = 0.0;
  };
  struct LogThrottle {
    ros::WallTime last;
    uint64_t suppressed = 0;
  };

  void onFrame(const sensor_msgs::ImageConstPtr& image, const sensor_msgs::CameraInfoConstPtr& info,
               const sensor_msgs::ImageConstPtr& depth);
  void onImageFrame(const sensor_msgs::ImageConstPtr& image, const sensor_msgs::CameraInfoConstPtr& info);
  void onPose(const geometry_msgs::PoseStampedConstPtr& pose);
  void onMapPoints(const sensor_msgs::PointCloud2ConstPtr& cloud);
  void onRawImage(const sensor_msgs::ImageConstPtr& image);
  void workerLoop();
  void process(const PendingFrame& frame);
  /// The camera pose at the image stamp, or a drop reason and message.
  std::optional<CameraPose> findPose(const PendingFrame& frame, std::string& reason, std::string& message);
  std::optional<CameraPose> findPoseTf(const std::string& camera_frame, const ros::Time& stamp,
                                       std::string& reason, std::string& message);
  std::optional<CameraPose> findPoseTopic(const ros::Time& stamp, std::string& reason, std::string& message);
  void drop(const std::string& reason, const std::string& message, const ros::Time& stamp);
  void onPublishTimer(const ros::WallTimerEvent&);
  void publishSelection();
  void publishStatistics();

  bool getNextViews(view_selection::GetNextViews::Request& req, view_selection::GetNextViews::Response& res);
  bool getSelection(view_selection::GetSelection::Request& req, view_selection::GetSelection::Response& res);
  bool exportSelection(view_selection::Export::Request& req, view_selection::Export::Response& res);
  bool reset(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);

  ros::NodeHandle nh_, pnh_;
  NodeConfig config_;

  // State of the method: everything below is guarded by state_mutex_.
  mutable std::mutex state_mutex_;
  std::unique_ptr<ViewSelector> selector_;
  Selection selection_;                                // selector_->select() after the last keyframe
  std::vector<sensor_msgs::ImageConstPtr> images_;     // by keyframe id, with ~save_keyframe_images
  std::optional<double> last_stamp_;                   // of the last frame offered to the core
  uint64_t version_ = 0;                               // bumps on every change of the selection
  uint64_t generation_ = 0;                            // bumps on ~reset

  // Input statistics, guarded by stats_mutex_.
  std::mutex stats_mutex_;
  Statistics stats_;
  uint64_t stats_version_ = 0;
  std::map<std::string, LogThrottle> log_throttle_;
  std::atomic<uint64_t> raw_images_{0};

  // Frames waiting for the worker.
  std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<PendingFrame> queue_;
  std::atomic<bool> stopping_{false};
  std::thread worker_;

  // Poses from the `pose` topic, ascending stamp.
  std::mutex pose_mutex_;
  std::condition_variable pose_cv_;
  std::deque<geometry_msgs::PoseStampedConstPtr> poses_;

  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;

  image_transport::ImageTransport it_;
  image_transport::SubscriberFilter image_sub_, depth_sub_;
  message_filters::Subscriber<sensor_msgs::CameraInfo> info_sub_;
  using SyncDepth = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo,
                                                                    sensor_msgs::Image>;
  using SyncImage = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo>;
  std::unique_ptr<message_filters::Synchronizer<SyncDepth>> sync_depth_;
  std::unique_ptr<message_filters::Synchronizer<SyncImage>> sync_image_;
  ros::Subscriber pose_sub_, points_sub_;

  ros::Publisher selection_pub_, markers_pub_, statistics_pub_;
  ros::ServiceServer next_views_srv_, selection_srv_, export_srv_, reset_srv_;
  ros::WallTimer publish_timer_;
  uint64_t published_version_ = ~uint64_t{0};
  uint64_t published_stats_version_ = ~uint64_t{0};
  ros::WallTime last_publish_;
  ros::WallTime started_;
};

}  // namespace ros_node
}  // namespace view_selection
