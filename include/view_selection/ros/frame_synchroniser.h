// Matches each image with the camera_info and depth nearest to its stamp, so that no image is
// lost without a count. message_filters' ApproximateTime minimises each set's spread and
// silently discards images when depth stamps wander around half a frame period from the colour
// stamps (as in the TUM benchmark's recordings: 72 of 500 kitchen frames with +-12 ms of jitter
// on a 15 ms offset); here every image becomes a frame or a drop with its reason.
//
// An image waits until each partner input has a message at its stamp, or one after its stamp
// that arrived after the image (then the nearest is known: stamps of one input increase), or
// until a partner input it still lacks has been silent for `timeout` when its partners so far are
// near enough (the last image of a bag has no later partner), or for `unmatched_timeout` when
// they are not (one TCP connection of a loaded publisher can stall for a second and more, and
// then still bring the partner), or until more than `max_waiting` images wait. An input that is
// still delivering older messages lags behind: its silence starts at its last message. A partner may serve two images
// (a depth stream slower than the colour stream). No ROS master needed: times come from the
// caller, which makes it testable on its own.
//
// Time jumps (a bag played again or looped, a restarted SLAM system): each input's stamps
// increase within one timeline. A camera_info or depth stamped more than `time_jump` before the
// newest of its input starts that input's new timeline: the older messages of that input are
// forgotten (they would otherwise be the nearest partners of the new images). For images the
// caller asks first (isTimeJump) and starts the new session itself (startTimeline), because the
// images waiting then belong to the session that ended.
#pragma once

#include "view_selection/ros/keyframe_worker.h"

#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <algorithm>
#include <deque>
#include <string>
#include <vector>

namespace view_selection::ros_node {

struct SynchroniserConfig {
  bool use_depth = true;
  double max_spread = 0.03;   ///< [s] largest |partner stamp - image stamp|; 0: any
  double timeout = 1.0;       ///< [s, caller's clock] longest silence of an input an image lacks, its partners near enough
  size_t max_waiting = 10;    ///< images waiting; beyond, the oldest is matched at once
  size_t max_partners = 100;  ///< camera_info and depth messages kept, per input
  double time_jump = 1.0;     ///< [s] a stamp this much before its input's newest: a new timeline; 0: never
  double unmatched_timeout = 3.0;  ///< [s, caller's clock] likewise, while no partner is near enough
};

/// What one call decided: frames for the worker, and images dropped with the reason's words.
struct SynchronisedFrames {
  struct Drop {
    ros::Time stamp;
    std::string message;
    uint64_t generation = 0;  ///< the image's, as addImage was given it
  };
  std::vector<PendingFrame> frames;
  std::vector<Drop> drops;
  /// Of `frames`, those released on a timeout (or a full queue) before a later partner could
  /// rule out a nearer one: their pairing depended on when messages arrived.
  size_t undecided = 0;
};

class FrameSynchroniser {
 public:
  explicit FrameSynchroniser(SynchroniserConfig config) : config_(config) {}

  /// Each add and poll returns the images it decided, in arrival order. `now` [s] is any
  /// steady clock (the node passes wall time). `generation`: the caller's session when the image
  /// arrived, handed on in its frame (PendingFrame::generation) or drop.
  SynchronisedFrames addImage(const sensor_msgs::ImageConstPtr& image, double now,
                              uint64_t generation = 0);
  SynchronisedFrames addCameraInfo(const sensor_msgs::CameraInfoConstPtr& info, double now);
  SynchronisedFrames addDepth(const sensor_msgs::ImageConstPtr& depth, double now);
  /// Decides the images that waited `timeout` or longer.
  SynchronisedFrames poll(double now);
  /// Forgets everything; waiting images are neither output nor counted.
  void clear();
  /// Whether an image at `stamp` is more than `time_jump` before the newest image so far (then
  /// `*newest` is that newest stamp).
  bool isTimeJump(const ros::Time& stamp, ros::Time* newest = nullptr) const;
  /// An image stamp seen before (a session continued from a file): later images more than
  /// `time_jump` before it are a time jump.
  void noteImageStamp(const ros::Time& stamp) { newest_image_ = std::max(newest_image_, stamp); }
  /// Images start a new timeline: the waiting images are forgotten (neither output nor counted)
  /// and the newest image stamp with them. Partners stay: each input starts its own new
  /// timeline when its stamps go back.
  void startTimeline();
  /// Forgets the waiting images that arrived in a generation before `generation` (a ~reset
  /// since), and their stamps: an image earlier than theirs is no time jump (the session starts
  /// over). Returns how many.
  size_t discardWaitingBefore(uint64_t generation);

  size_t waiting() const { return waiting_.size(); }
  const SynchroniserConfig& config() const { return config_; }

 private:
  struct Waiting {
    sensor_msgs::ImageConstPtr image;
    double arrived = 0.0;
    uint64_t order = 0;  ///< arrival count, over every input
    uint64_t generation = 0;
  };
  template <typename Ptr>
  struct Partner {
    Ptr message;
    uint64_t order = 0;
  };

  void release(double now, SynchronisedFrames& out);
  void prune();
  /// A partner stamped more than time_jump before its input's newest: forgets that input's
  /// earlier messages.
  template <typename P>
  void newTimelineIfJump(std::deque<P>& messages, const ros::Time& stamp);

  SynchroniserConfig config_;
  std::deque<Waiting> waiting_;
  std::deque<Partner<sensor_msgs::CameraInfoConstPtr>> infos_;  // ascending stamp
  std::deque<Partner<sensor_msgs::ImageConstPtr>> depths_;      // ascending stamp
  double info_arrived_ = 0.0;   ///< caller's clock at the last camera_info (0: none yet)
  double depth_arrived_ = 0.0;  ///< likewise, depth
  ros::Time last_released_;
  ros::Time newest_image_;  ///< of this timeline; zero: none yet
  uint64_t arrivals_ = 0;
};

}  // namespace view_selection::ros_node
