// Every parameter of view_selection_node: the node's own (frames, poses, input, output) and the
// method's (core::ViewSelectorConfig, points::PointSourceParams), each with its default in its
// struct and listed once by visitParameters(); loadNodeConfig reads them all from ~parameters.
#pragma once

#include "view_selection/core/parameters.h"
#include "view_selection/core/pose_correction.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/points/point_source_factory.h"

#include <ros/node_handle.h>

#include <string>
#include <vector>

namespace view_selection::ros_node {

/// tf, or a topic of geometry_msgs/PoseStamped ("topic"), nav_msgs/Odometry or
/// geometry_msgs/PoseWithCovarianceStamped.
enum class PoseSource { kTf, kTopic, kOdometry, kPoseWithCovariance };
inline constexpr core::EnumNames<PoseSource, 4> kPoseSourceNames{
    {{PoseSource::kTf, "tf"},
     {PoseSource::kTopic, "topic"},
     {PoseSource::kOdometry, "odometry"},
     {PoseSource::kPoseWithCovariance, "pose_with_covariance"}}};

struct NodeConfig {
  std::string world_frame = "world";  ///< frame of every pose and marker (leading '/' removed)
  std::string camera_frame;           ///< optical frame of the camera; "" = the image's frame_id
  std::string body_frame;  ///< topic sources: frame the poses are of; "" = see visitParameters
  PoseSource pose_source = PoseSource::kTf;
  /// [s, wall] how long a frame waits for its pose: odometry at 10 Hz comes up to 0.1 s after a
  /// frame's stamp, plus the SLAM system's latency.
  double pose_timeout = 0.5;
  /// [s] topic sources: the poses on either side of a frame must each be this close (odometry
  /// at 10 Hz or faster, on any clock; docs/node.md has the measured interpolation error).
  double pose_max_time_difference = 0.12;
  int queue_size = 90;                     ///< images waiting for their camera_info and depth
  int subscriber_queue_size = 100;         ///< roscpp queue of each of image, camera_info, depth
  double max_stamp_spread = 0.03;  ///< [s] largest |camera_info or depth stamp - image stamp|
  double sync_timeout = 1.0;       ///< [s, wall] longest silence of an input an image lacks
  double sync_unmatched_timeout = 3.0;  ///< [s, wall] likewise, while no partner is near enough
  int max_pending_frames = 30;     ///< frames waiting for the worker before the oldest is dropped
  /// [s] image stamps that go back by more than this start a new session (a bag played again or
  /// looped, a restarted SLAM system); 0: never (every such frame is an out_of_order_stamp drop).
  double time_jump_threshold = 1.0;
  bool use_depth = true;           ///< subscribe to `depth` and synchronise it
  /// raw: sensor_msgs/Image on `image`; compressed: sensor_msgs/CompressedImage on
  /// `image`/compressed (JPEG or PNG), decoded by the node (no image_transport plugin needed).
  std::string image_transport = "raw";
  /// raw, compressedDepth (`depth`/compressedDepth) or compressed (`depth`/compressed, PNG).
  std::string depth_image_transport = "raw";
  /// depth | features | map | auto; loadNodeConfig resolves auto (depth with use_depth, else
  /// features, as select_views does by the folder).
  std::string point_source = "auto";
  double depth_16u_metres_per_unit = 0.001;  ///< 16UC1 depth scale (millimetres)
  double publish_period = 0.5;        ///< [s, wall] minimum interval between ~selection messages
  bool save_keyframe_images = false;  ///< keep keyframe images for ~export
  /// Above this many keyframes ~selection carries only what changed (at most this many views a
  /// message) and ~markers a summary of at most about this many views; 0 = always everything.
  int publish_max_views = 1000;
  /// With save_keyframe_images: keyframe images held in RAM [MB]; older ones go to image_dir.
  double image_cache_mb = 512.0;
  /// Folder for the images beyond image_cache_mb; "" = a temporary folder of the node's own.
  std::string image_dir;
  double marker_scale = 0.1;          ///< frustum depth in RViz [m, scene units]
  /// The session is saved here (on shutdown, every autosave_keyframes keyframes, ~save_state)
  /// and continued from it at start; "" = off; relative to ROS_HOME (default ~/.ros).
  std::string state_file;
  int autosave_keyframes = 10;  ///< 0: save only on shutdown and ~save_state

  /// ~pairs: a selected pair is announced once it is still selected this many keyframes later.
  int pair_stable_keyframes = 3;
  /// [s, wall] ~pairs: when no frame arrived for this long, every selected pair is announced.
  double pair_flush_idle = 0.5;
  int pair_history = 1000;  ///< ~pairs messages kept for ~get_pairs
  /// Each keyframe's image is written here as it is accepted (~write_keyframe_images); "" = off.
  std::string keyframe_image_dir;

  double keyframe_verdict_timeout = 1.0;  ///< [s, wall] external policy: longest wait for a verdict
  double keyframe_stamp_tolerance = 0.001;  ///< [s] external policy: stamp match
  bool use_path_corrections = false;        ///< subscribe to `path` (nav_msgs/Path, loop closures)
  /// Frames after a path take its newest correction (a pose source that is not corrected itself).
  bool correct_later_frames = false;
  /// tf pose source: the SLAM system's odometry frame (RTAB-Map: odom), whose link to
  /// world_frame is its own loop correction; corrections are measured against the camera's poses
  /// in it. "" = against the world_frame poses.
  std::string odom_frame;
  core::PoseCorrectionConfig corrections;   ///< matching a path to keyframes, thresholds

  core::ViewSelectorConfig selector;       ///< keyframe policy, matrix gates, selection
  points::PointSourceParams point_params;  ///< each point source's parameters

  /// The frame path corrections are measured in: ~odom_frame with a tf source and
  /// ~use_path_corrections, else "" (the poses the source gives, in world_frame).
  std::string correctionFrame() const {
    return use_path_corrections && pose_source == PoseSource::kTf ? odom_frame : std::string();
  }

  /// The node's own parameters, then the method's, then the point sources'.
  void visitParameters(core::ParameterVisitor& v);
};

/// Normalises a tf frame id: strips leading '/' (old bags write "/world"), tf2 rejects them.
std::string normaliseFrameId(const std::string& frame_id);

/// Reads ~parameters from `private_nh`. Throws core::InvalidArgument naming the parameter and the
/// accepted range when one is out of range, of the wrong type or unknown in a choice.
NodeConfig loadNodeConfig(const ros::NodeHandle& private_nh);

/// Parameters set under `private_nh` that no visitParameters() lists (misspelled ones), by name.
/// Names with a '/' (other components' namespaces, e.g. image_transport's) are not judged.
std::vector<std::string> unknownParameters(const ros::NodeHandle& private_nh);

}  // namespace view_selection::ros_node
