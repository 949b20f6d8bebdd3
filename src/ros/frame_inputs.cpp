#include "view_selection/ros/frame_inputs.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/parameters.h"

#include "view_selection/ros/compressed_images.h"
#include "view_selection/ros/conversions.h"

#include <boost/make_shared.hpp>

#include <cmath>
#include <limits>

namespace view_selection::ros_node {

namespace {
ros::NodeHandle onQueue(ros::NodeHandle nh, ros::CallbackQueue* queue) {
  nh.setCallbackQueue(queue);
  return nh;
}
}  // namespace

namespace {
SynchroniserConfig synchroniserConfig(const NodeConfig& c) {
  SynchroniserConfig s;
  s.use_depth = c.use_depth;
  s.max_spread = c.max_stamp_spread;
  s.timeout = c.sync_timeout;
  s.unmatched_timeout = c.sync_unmatched_timeout;
  s.max_waiting = static_cast<size_t>(c.queue_size);
  s.max_partners = static_cast<size_t>(std::max(c.queue_size, c.subscriber_queue_size));
  s.time_jump = c.time_jump_threshold;
  return s;
}
double wallNow() { return ros::WallTime::now().toSec(); }
}  // namespace

FrameInputs::FrameInputs(const NodeConfig& config, ros::NodeHandle nh, ros::NodeHandle private_nh,
                         KeyframeWorker& worker, InputStatistics& statistics)
    : config_(config),
      nh_(nh),
      worker_(worker),
      statistics_(statistics),
      sync_(synchroniserConfig(config)),
      input_nh_(onQueue(nh, &input_queue_)),
      it_(input_nh_),
      input_spinner_(1, &input_queue_) {
  if (config_.point_source == "map")
    points_sub_ = nh_.subscribe("points", kMapQueue, &FrameInputs::onMapPoints, this);
  // The roscpp queues hold what arrives while the input thread is busy.
  const uint32_t q = static_cast<uint32_t>(config_.subscriber_queue_size);
  // Compressed transports as image_transport names their topics (<base>/<transport>, the base
  // remapped), decoded here: Debian packages only image_transport's raw plugin.
  if (config_.image_transport == "compressed")
    compressed_image_sub_ = input_nh_.subscribe(input_nh_.resolveName("image") + "/compressed", q,
                                                &FrameInputs::onCompressedImage, this);
  else
    image_sub_ =
        it_.subscribe("image", q, &FrameInputs::onImage, this,
                      image_transport::TransportHints("raw", ros::TransportHints(), private_nh));
  info_sub_ = input_nh_.subscribe("camera_info", q, &FrameInputs::onCameraInfo, this);
  if (config_.use_depth && config_.depth_image_transport != "raw")
    compressed_depth_sub_ =
        input_nh_.subscribe(input_nh_.resolveName("depth") + "/" + config_.depth_image_transport,
                            q, &FrameInputs::onCompressedDepth, this);
  else if (config_.use_depth)
    depth_sub_ =
        it_.subscribe("depth", q, &FrameInputs::onDepth, this,
                      image_transport::TransportHints("raw", ros::TransportHints(), private_nh,
                                                      "depth_image_transport"));
  // A session continued from ~state_file: an image more than ~time_jump_threshold before its
  // last frame is a time jump too.
  if (const std::optional<double> last = worker_.lastStamp())
    if (*last > 0.0) sync_.noteImageStamp(ros::Time(*last));
  poll_timer_ =
      input_nh_.createWallTimer(ros::WallDuration(kPollPeriod), [this](const ros::WallTimerEvent&) {
        std::lock_guard<std::mutex> lock(sync_mutex_);
        discardEarlierGenerations();
        deliver(sync_.poll(wallNow()));
      });
  check_timer_ = private_nh.createWallTimer(
      ros::WallDuration(kCheckPeriod), [this](const ros::WallTimerEvent&) { checkUnmatched(); });
  input_spinner_.start();
}

FrameInputs::~FrameInputs() {
  input_spinner_.stop();  // no input callback runs from here on
  poll_timer_.stop();
  check_timer_.stop();
  image_sub_.shutdown();
  depth_sub_.shutdown();
  compressed_image_sub_.shutdown();
  compressed_depth_sub_.shutdown();
  info_sub_.shutdown();
  points_sub_.shutdown();
  // The images still waiting for a partner are decided now with what came (as their timeouts
  // would): each becomes a frame for the worker, which handles it before it stops, or a
  // counted drop. Nothing that arrived is lost at shutdown.
  std::lock_guard<std::mutex> lock(sync_mutex_);
  discardEarlierGenerations();
  deliver(sync_.poll(std::numeric_limits<double>::infinity()));
}

void FrameInputs::onImage(const sensor_msgs::ImageConstPtr& image) { addImage(image); }

void FrameInputs::onCompressedImage(const sensor_msgs::CompressedImageConstPtr& msg) {
  sensor_msgs::ImageConstPtr image;
  try {
    image = decodeCompressedImage(*msg);  // outside the lock: decoding takes milliseconds
  } catch (const core::InvalidInput& e) {
    std::lock_guard<std::mutex> lock(sync_mutex_);
    image = corruptStandIn(msg->header, "bad_image",
                           "'" + input_nh_.resolveName("image") + "/compressed' (format '" +
                               msg->format + "'): " + e.what());
  }
  addImage(image);
}

void FrameInputs::onCompressedDepth(const sensor_msgs::CompressedImageConstPtr& msg) {
  statistics_.arrived(InputStatistics::Input::kDepth);
  sensor_msgs::ImageConstPtr depth;
  try {
    depth = config_.depth_image_transport == "compressedDepth" ? decodeCompressedDepth(*msg)
                                                               : decodeCompressedImage(*msg);
  } catch (const core::InvalidInput& e) {
    std::lock_guard<std::mutex> lock(sync_mutex_);
    depth = corruptStandIn(msg->header, "bad_depth",
                           "'" + input_nh_.resolveName("depth") + "/" +
                               config_.depth_image_transport + "' (format '" + msg->format +
                               "'): " + e.what());
  }
  addDepth(depth);
}

sensor_msgs::ImageConstPtr FrameInputs::corruptStandIn(const std_msgs::Header& header,
                                                       const std::string& reason,
                                                       const std::string& why) {
  auto stand_in = boost::make_shared<sensor_msgs::Image>();
  stand_in->header = header;
  // Kept while the synchroniser may hold it: as many as it keeps of each input, and waiting.
  const size_t keep = sync_.config().max_partners + sync_.config().max_waiting + 1;
  while (corrupt_.size() >= keep) corrupt_.pop_front();
  corrupt_.push_back({stand_in, reason, why});
  return stand_in;
}

void FrameInputs::discardEarlierGenerations() {
  // Images that arrived before a ~reset belong to the session it ended: they never become
  // frames of the new one (push() discards those already released).
  const uint64_t generation = worker_.generation();
  if (generation == sync_generation_) return;
  sync_generation_ = generation;
  sync_.discardWaitingBefore(generation);
}

void FrameInputs::addImage(const sensor_msgs::ImageConstPtr& image) {
  std::lock_guard<std::mutex> lock(sync_mutex_);
  discardEarlierGenerations();
  ros::Time newest;
  if (sync_.isTimeJump(image->header.stamp, &newest)) {
    // Before this image is counted: it is the new session's first.
    sync_.startTimeline();  // the images waiting are the old session's
    last_seq_.reset();
    worker_.timeJump(newest, image->header.stamp);
    sync_generation_ = worker_.generation();
  }
  statistics_.arrived(InputStatistics::Input::kImage);
  const uint32_t seq = image->header.seq;
  // Publishers that number their images (rosbag play of a recording, camera drivers): a gap is
  // images that never reached this callback. Publishers that leave seq at 0 show no gap.
  if (last_seq_ && seq > *last_seq_ + 1 && seq - *last_seq_ <= kMaxSeqGap) {
    const uint32_t lost = seq - *last_seq_ - 1;
    for (uint32_t n = 0; n < lost; ++n)
      statistics_.dropInput("lost_before_node",
                       "the image after seq " + std::to_string(*last_seq_) + " is seq " +
                           std::to_string(seq) + ": " + std::to_string(lost) + " image(s) on '" +
                           nh_.resolveName("image") +
                           "' never reached the node (a queue before it was full; raise "
                           "~subscriber_queue_size, or the publisher dropped them)",
                       image->header.stamp);
  }
  last_seq_ = seq;
  deliver(sync_.addImage(image, wallNow(), sync_generation_));
}

void FrameInputs::onCameraInfo(const sensor_msgs::CameraInfoConstPtr& info) {
  statistics_.arrived(InputStatistics::Input::kCameraInfo);
  std::lock_guard<std::mutex> lock(sync_mutex_);
  discardEarlierGenerations();
  deliver(sync_.addCameraInfo(info, wallNow()));
}

void FrameInputs::onDepth(const sensor_msgs::ImageConstPtr& depth) {
  statistics_.arrived(InputStatistics::Input::kDepth);
  addDepth(depth);
}

void FrameInputs::addDepth(const sensor_msgs::ImageConstPtr& depth) {
  std::lock_guard<std::mutex> lock(sync_mutex_);
  discardEarlierGenerations();
  deliver(sync_.addDepth(depth, wallNow()));
}

void FrameInputs::deliver(SynchronisedFrames decided) {
  const uint64_t generation = worker_.generation();
  for (const auto& drop : decided.drops)
    if (drop.generation == generation)  // else the image belongs to a session that ended
      statistics_.dropInput("unsynchronised", drop.message, drop.stamp);
  for (PendingFrame& frame : decided.frames) {
    if (frame.generation != generation) continue;  // likewise (push() checks it again)
    const Corrupt* corrupt = nullptr;
    for (const Corrupt& c : corrupt_)
      if (c.stand_in == frame.image || (frame.depth && c.stand_in == frame.depth)) corrupt = &c;
    if (!corrupt) {
      worker_.push(std::move(frame));  // counts it received
      continue;
    }
    // A frame whose image or depth did not decode: received, and dropped for that.
    const uint64_t session = statistics_.frameReceived();
    statistics_.drop(session, corrupt->reason,
                     "stamp " + stampText(frame.image->header.stamp) + ": " + corrupt->message,
                     frame.image->header.stamp);
  }
  statistics_.pairedOnTimeout(decided.undecided);
  statistics_.setImagesInSynchroniser(sync_.waiting());
}

void FrameInputs::checkUnmatched() {
  // Images arrive but never become frames: the synchroniser finds no partner for them.
  const InputStatistics::Counts counts = statistics_.counts();
  if (counts.images_arrived < kUnmatchedWarning || counts.frames_received > 0) return;
  ROS_WARN_STREAM("view_selection: "
                  << counts.images_arrived << " images arrived on '" << nh_.resolveName("image")
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
