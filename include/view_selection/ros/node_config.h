// Every parameter of view_selection_node, read from the private namespace and validated in one
// place. Defaults live in the structs (here and in the core's ViewSelectorConfig).
#pragma once

#include "view_selection/core/point_source_factory.h"
#include "view_selection/core/view_selector.h"

#include <ros/node_handle.h>

#include <string>

namespace view_selection {
namespace ros_node {

enum class PoseSource { kTf, kTopic };

struct NodeConfig {
  ViewSelectorConfig selector;        ///< keyframe policy, sampling, matrix gates, selection
  std::string world_frame = "world";  ///< frame of every pose and marker (leading '/' removed)
  std::string camera_frame;           ///< optical frame of the camera; "" = the image's frame_id
  PoseSource pose_source = PoseSource::kTf;
  double pose_timeout = 0.1;          ///< [s, wall] how long a frame waits for its pose
  double pose_max_time_difference = 0.02;  ///< [s] topic source: nearest pose must be this close
  int queue_size = 10;                ///< message_filters ApproximateTime queue
  int max_pending_frames = 30;        ///< frames waiting for the worker before the oldest is dropped
  bool use_depth = true;              ///< subscribe to `depth` and synchronise it
  std::string point_source = "depth"; ///< resolved: depth | features | map (auto: depth with use_depth, else features)
  PointSourceParams point_params;     ///< each source's parameters (depth grid, features, map)
  double depth_16u_metres_per_unit = 0.001;  ///< 16UC1 depth scale (millimetres)
  double publish_period = 0.5;        ///< [s, wall] minimum interval between ~selection messages
  bool save_keyframe_images = false;  ///< keep keyframe images for ~export
  double marker_scale = 0.1;          ///< frustum depth in RViz [m, scene units]
};

/// Normalises a tf frame id: strips leading '/' (old bags write "/world"), tf2 rejects them.
std::string normaliseFrameId(const std::string& frame_id);

/// Reads ~parameters from `private_nh`. Throws InvalidArgument naming the parameter and the
/// accepted range when one is out of range, of the wrong type or unknown in a choice.
NodeConfig loadNodeConfig(const ros::NodeHandle& private_nh);

}  // namespace ros_node
}  // namespace view_selection
