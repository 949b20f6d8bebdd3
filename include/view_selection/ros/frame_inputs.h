// The node's inputs: `image`, `camera_info` and (with ~use_depth) `depth`, through image_transport,
// matched by stamp (FrameSynchroniser: nearest camera_info and depth within ~max_stamp_spread);
// and, for the "map" point source, map points on `points`. Frames go to the worker; bad clouds
// are counted as drops.
//
// No image is lost without a count: the three inputs have a callback queue and a thread of their
// own (nothing else on the node's spinner delays them), roscpp queues of ~subscriber_queue_size,
// every arrival is counted, every image becomes a frame or an "unsynchronised" drop, and images
// missing from the sequence numbers of `image` (lost in a full queue before the node) are counted
// as "lost_before_node".
#pragma once

#include "view_selection/ros/input_statistics.h"
#include "view_selection/ros/keyframe_worker.h"
#include "view_selection/ros/node_config.h"

#include "view_selection/ros/frame_synchroniser.h"

#include <image_transport/image_transport.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>

#include <ros/callback_queue.h>

#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>

namespace view_selection::ros_node {

class FrameInputs {
 public:
  /// Subscribes (relative names on `nh`, transports from `private_nh`'s ~image_transport and
  /// ~depth_image_transport). Throws what image_transport throws for an unknown transport.
  FrameInputs(const NodeConfig& config, ros::NodeHandle nh, ros::NodeHandle private_nh,
              KeyframeWorker& worker, InputStatistics& statistics);
  /// Stops the inputs, then hands the images still waiting in the synchroniser to the worker
  /// (or counts them as drops): none is lost at shutdown.
  ~FrameInputs();

 private:
  static constexpr uint32_t kMapQueue = 2;      ///< map clouds: each replaces the last, keep few
  static constexpr double kCheckPeriod = 10.0;  ///< [s, wall] between checks for unmatched images
  static constexpr double kPollPeriod = 0.05;   ///< [s, wall] between synchroniser timeout checks
  static constexpr uint64_t kUnmatchedWarning = 30;  ///< images without a frame before warning
  /// A jump in header.seq larger than this is a restarted publisher, not lost images.
  static constexpr uint32_t kMaxSeqGap = 1000;

  void onImage(const sensor_msgs::ImageConstPtr& image);
  void onCameraInfo(const sensor_msgs::CameraInfoConstPtr& info);
  void onDepth(const sensor_msgs::ImageConstPtr& depth);
  /// ~image_transport compressed, ~depth_image_transport compressedDepth or compressed: decoded
  /// here; a payload that does not decode enters the synchroniser as a stand-in (the header
  /// only), so that the frame it belongs to is dropped with the reason (bad_image, bad_depth).
  void onCompressedImage(const sensor_msgs::CompressedImageConstPtr& image);
  void onCompressedDepth(const sensor_msgs::CompressedImageConstPtr& depth);
  /// Counts the image, checks its sequence number and its stamp (a time jump: a new session),
  /// and hands it to the synchroniser.
  void addImage(const sensor_msgs::ImageConstPtr& image);
  /// Under sync_mutex_: after a ~reset, forgets the images waiting from before it.
  void discardEarlierGenerations();
  void addDepth(const sensor_msgs::ImageConstPtr& depth);
  /// Frames to the worker, drops to the statistics (under sync_mutex_).
  void deliver(SynchronisedFrames decided);
  /// Under sync_mutex_: a stand-in for a payload that did not decode, with its drop.
  sensor_msgs::ImageConstPtr corruptStandIn(const std_msgs::Header& header,
                                            const std::string& reason, const std::string& why);
  void onMapPoints(const sensor_msgs::PointCloud2ConstPtr& cloud);
  void checkUnmatched();

  const NodeConfig& config_;
  ros::NodeHandle nh_;
  KeyframeWorker& worker_;
  InputStatistics& statistics_;

  std::mutex sync_mutex_;  // the synchroniser and the sequence check
  FrameSynchroniser sync_;
  std::optional<uint32_t> last_seq_;
  uint64_t sync_generation_ = 0;  ///< the worker's generation the waiting images arrived in
  struct Corrupt {
    sensor_msgs::ImageConstPtr stand_in;
    std::string reason, message;
  };
  std::deque<Corrupt> corrupt_;  ///< stand-ins the synchroniser may still hold, oldest first

  ros::CallbackQueue input_queue_;  ///< image, camera_info, depth, the synchroniser's timer
  ros::NodeHandle input_nh_;
  image_transport::ImageTransport it_;
  image_transport::Subscriber image_sub_, depth_sub_;
  ros::Subscriber compressed_image_sub_, compressed_depth_sub_;
  ros::Subscriber info_sub_;
  ros::WallTimer poll_timer_;
  ros::Subscriber points_sub_;
  ros::WallTimer check_timer_;
  ros::AsyncSpinner input_spinner_;  // last: started once every subscriber exists
};

}  // namespace view_selection::ros_node
