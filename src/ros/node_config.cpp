#include "view_selection/ros/node_config.h"

#include "view_selection/core/exceptions.h"

#include <cmath>
#include <sstream>
#include <vector>

namespace view_selection {
namespace ros_node {

namespace {

std::string paramName(const ros::NodeHandle& nh, const std::string& key) {
  return nh.resolveName(key);
}

template <typename T>
bool readParam(const ros::NodeHandle& nh, const std::string& key, T& value, const char* type) {
  if (!nh.hasParam(key)) return false;
  if (!nh.getParam(key, value))
    throw InvalidArgument("parameter " + paramName(nh, key) + " must be " + type);
  return true;
}

double readReal(const ros::NodeHandle& nh, const std::string& key, double def, double lo, double hi) {
  double v = def;
  readParam(nh, key, v, "a number");
  if (!std::isfinite(v) || v < lo || v > hi) {
    std::ostringstream s;
    s << "parameter " << paramName(nh, key) << " = " << v << " is out of range [" << lo << ", " << hi << "]";
    throw InvalidArgument(s.str());
  }
  return v;
}

int readInt(const ros::NodeHandle& nh, const std::string& key, int def, int lo, int hi) {
  int v = def;
  readParam(nh, key, v, "an integer");
  if (v < lo || v > hi) {
    std::ostringstream s;
    s << "parameter " << paramName(nh, key) << " = " << v << " is out of range [" << lo << ", " << hi << "]";
    throw InvalidArgument(s.str());
  }
  return v;
}

bool readBool(const ros::NodeHandle& nh, const std::string& key, bool def) {
  bool v = def;
  readParam(nh, key, v, "true or false");
  return v;
}

std::string readChoice(const ros::NodeHandle& nh, const std::string& key, const std::string& def,
                       const std::vector<std::string>& choices) {
  std::string v = def;
  readParam(nh, key, v, "a string");
  for (const auto& c : choices)
    if (c == v) return v;
  std::string list;
  for (const auto& c : choices) list += (list.empty() ? "" : ", ") + c;
  throw InvalidArgument("parameter " + paramName(nh, key) + " = '" + v + "' is not one of: " + list);
}

}  // namespace

std::string normaliseFrameId(const std::string& frame_id) {
  const size_t first = frame_id.find_first_not_of('/');
  return first == std::string::npos ? std::string() : frame_id.substr(first);
}

NodeConfig loadNodeConfig(const ros::NodeHandle& nh) {
  NodeConfig c;
  std::string text;
  text = c.world_frame;
  readParam(nh, "world_frame", text, "a string");
  c.world_frame = normaliseFrameId(text);
  if (c.world_frame.empty())
    throw InvalidArgument("parameter " + paramName(nh, "world_frame") + " must name a frame");
  text = c.camera_frame;
  readParam(nh, "camera_frame", text, "a string");
  c.camera_frame = normaliseFrameId(text);
  c.pose_source = readChoice(nh, "pose_source", "tf", {"tf", "topic"}) == "tf" ? PoseSource::kTf
                                                                               : PoseSource::kTopic;
  c.pose_timeout = readReal(nh, "pose_timeout", c.pose_timeout, 0.0, 60.0);
  c.pose_max_time_difference =
      readReal(nh, "pose_max_time_difference", c.pose_max_time_difference, 0.0, 10.0);
  c.queue_size = readInt(nh, "queue_size", c.queue_size, 1, 10000);
  c.max_pending_frames = readInt(nh, "max_pending_frames", c.max_pending_frames, 1, 100000);
  c.use_depth = readBool(nh, "use_depth", c.use_depth);
  c.depth_16u_metres_per_unit =
      readReal(nh, "depth_16u_metres_per_unit", c.depth_16u_metres_per_unit, 1e-9, 1e3);
  c.publish_period = readReal(nh, "publish_period", c.publish_period, 0.0, 3600.0);
  c.save_keyframe_images = readBool(nh, "save_keyframe_images", c.save_keyframe_images);
  c.marker_scale = readReal(nh, "marker_scale", c.marker_scale, 1e-6, 1e6);

  // The core's parameters, named as select_views' options (METHOD.md defaults in the structs).
  ViewSelectorConfig& v = c.selector;
  auto& kf = v.keyframes;
  kf.mode = keyframeModeFromString(
      readChoice(nh, "keyframe_policy", "motion", {"every_frame", "every_nth", "motion"}));
  kf.every_n = readInt(nh, "every_n", kf.every_n, 1, 1000000);
  kf.min_translation = readReal(nh, "min_translation", kf.min_translation, 0.0, 1e9);
  kf.min_rotation_deg = readReal(nh, "min_rotation_deg", kf.min_rotation_deg, 0.0, 360.0);
  v.selection.k = readInt(nh, "k", v.selection.k, 1, 1000);
  v.selection.completion =
      completionModeFromString(readChoice(nh, "completion", "paper", {"paper", "reachable"}));
  auto& m = v.matrix;
  m.min_covisible_points = readInt(nh, "min_covisible_points", m.min_covisible_points, 1, 1000000);
  m.min_covisible_ratio = readReal(nh, "min_covisible_ratio", m.min_covisible_ratio, 0.0, 1.0);
  m.max_view_angle_deg = readReal(nh, "max_view_angle_deg", m.max_view_angle_deg, 0.0, 180.0);
  v.occlusion_test = readBool(nh, "occlusion_test", v.occlusion_test);
  const int grid = readInt(nh, "grid", v.depth.grid_cols, 1, 256);
  v.depth.grid_cols = v.depth.grid_rows = grid;

  // As select_views: auto is depth when there is depth, features otherwise.
  const std::string source = readChoice(nh, "point_source", "auto", {"auto", "depth", "features", "map"});
  c.point_source = source == "auto" ? (c.use_depth ? "depth" : "features") : source;
  if (c.point_source == "depth" && !c.use_depth)
    throw InvalidArgument("parameter " + paramName(nh, "point_source") +
                          " = depth needs depth images, but ~use_depth is false");
  PointSourceParams& pp = c.point_params;
  pp.depth = v.depth;
  pp.features.detector = readChoice(nh, "features", pp.features.detector, {"orb", "sift"});
  pp.features.max_features = readInt(nh, "max_features", pp.features.max_features, 1, 1000000);
  pp.map.max_depth = readReal(nh, "map_max_depth", pp.map.max_depth, 0.0, 1e9);
  pp.map.max_points = readInt(nh, "map_max_points", pp.map.max_points, 0, 100000000);
  pp.map.occlusion_test = v.occlusion_test;
  pp.validate();
  v.validate();
  return c;
}

}  // namespace ros_node
}  // namespace view_selection
