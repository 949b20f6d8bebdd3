#include "view_selection/ros/node_config.h"

#include "view_selection/core/exceptions.h"

#include <ros/param.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

namespace view_selection::ros_node {

void NodeConfig::visitParameters(core::ParameterVisitor& v) {
  v.section("Frames and poses");
  core::visitText(v, "world_frame", world_frame, {},
                  "frame of every pose, marker and selection (a leading '/' is removed)");
  core::visitText(v, "camera_frame", camera_frame, {},
                  "optical frame (z forward) of the camera; \"\" = the image's frame_id");
  core::visitChoice(v, "pose_source", pose_source, kPoseSourceNames,
                    "tf: look up world_frame <- camera frame at the image stamp; on `pose`, "
                    "interpolated at the image stamp: topic (geometry_msgs/PoseStamped), odometry "
                    "(nav_msgs/Odometry), pose_with_covariance "
                    "(geometry_msgs/PoseWithCovarianceStamped)");
  core::visitText(v, "body_frame", body_frame, {},
                  "topic sources: the frame the poses are of (ORB-SLAM2 camera_link, VINS body, "
                  "RTAB-Map base_link); its fixed transform to the optical frame is looked up "
                  "once from tf; \"\" = Odometry's child_frame_id, else the optical frame itself");
  core::visitReal(v, "pose_timeout", pose_timeout, 0.0, 60.0,
                  "how long a frame waits for its pose before it is dropped [s, wall]");
  core::visitReal(v, "pose_max_time_difference", pose_max_time_difference, 0.0, 10.0,
                  "topic sources: the poses on either side of the image stamp must each be this "
                  "close to it to be interpolated (a pose at the stamp is taken as it is); 0.12 "
                  "admits odometry at 10 Hz or faster on any clock, with 20 ms of jitter [s]");
  v.section("Input");
  core::visitInteger(v, "queue_size", queue_size, 1, 10000,
                     "images waiting for their camera_info and depth (3 s at 30 Hz); beyond, "
                     "the oldest is matched with what has arrived");
  core::visitInteger(v, "subscriber_queue_size", subscriber_queue_size, 1, 100000,
                     "roscpp queue of each input (image, camera_info, depth): what arrives while "
                     "the input thread is busy waits here; a full queue loses the oldest "
                     "(counted as lost_before_node from the images' header.seq)");
  core::visitReal(v, "max_stamp_spread", max_stamp_spread, 0.0, 10.0,
                  "each image takes the camera_info and the depth nearest to its stamp, when "
                  "they are at most this far from it; else it is dropped (unsynchronised); 0: "
                  "any [s]");
  core::visitReal(v, "sync_timeout", sync_timeout, 0.0, 60.0,
                  "an image waits for a camera_info and a depth at or after its stamp (then the "
                  "nearest is known) until the input it lacks has been silent this long (an "
                  "input still delivering older messages lags and may yet bring it), then takes "
                  "the nearest so far [s, wall]");
  core::visitReal(v, "sync_unmatched_timeout", sync_unmatched_timeout, 0.0, 60.0,
                  "as ~sync_timeout, for an image whose camera_info or depth within "
                  "~max_stamp_spread has not come yet: a stalled connection may still bring it; "
                  "then the image is dropped (unsynchronised); at least ~sync_timeout [s, wall]");
  core::visitInteger(
      v, "max_pending_frames", max_pending_frames, 1, 100000,
      "frames waiting for the worker; beyond, the oldest is dropped (worker_behind)");
  core::visitReal(v, "time_jump_threshold", time_jump_threshold, 0.0, 1e6,
                  "an image stamp more than this before the newest so far is a time jump (a bag "
                  "played again or looped, a restarted SLAM system): a new session starts, as "
                  "after ~reset (with ~state_file the old one is kept in the file named "
                  "state_file + .previous); smaller steps back are out_of_order_stamp drops; 0: "
                  "never [s]");
  core::visitFlag(v, "use_depth", use_depth,
                  "synchronise `depth` (16UC1 millimetres or 32FC1 metres) with the image");
  core::visitText(v, "image_transport", image_transport, {"raw", "compressed"},
                  "raw: sensor_msgs/Image on `image`; compressed: sensor_msgs/CompressedImage "
                  "(JPEG or PNG, as compressed_image_transport writes it) on `image`/compressed, "
                  "decoded by the node itself (no image_transport plugin needed)");
  core::visitText(v, "depth_image_transport", depth_image_transport,
                  {"raw", "compressedDepth", "compressed"},
                  "raw: sensor_msgs/Image on `depth`; compressedDepth: as "
                  "compressed_depth_image_transport writes it (16UC1 PNG, or 32FC1 as quantised "
                  "inverse depth) on `depth`/compressedDepth; compressed: a 16-bit PNG on "
                  "`depth`/compressed");
  core::visitText(v, "point_source", point_source, {"auto", "depth", "features", "map"},
                  "where sample points come from; auto = depth with use_depth, else features");
  core::visitReal(v, "depth_16u_metres_per_unit", depth_16u_metres_per_unit, 1e-9, 1e3,
                  "scale of 16UC1 depth (0.001: millimetres)");
  v.section("External keyframes (keyframe_policy: external)");
  core::visitReal(v, "keyframe_verdict_timeout", keyframe_verdict_timeout, 0.0, 60.0,
                  "a frame waits this long for the stamps on `keyframes` (nav_msgs/Path) to say "
                  "whether it is a keyframe, then is dropped (no_keyframe_verdict) [s, wall]");
  core::visitReal(v, "keyframe_stamp_tolerance", keyframe_stamp_tolerance, 0.0, 10.0,
                  "a frame is a keyframe when a stamp on `keyframes` is this close to its own, "
                  "and is not once a later stamp came [s]");
  v.section("Loop-closure corrections");
  core::visitFlag(v, "use_path_corrections", use_path_corrections,
                  "subscribe to `path` (nav_msgs/Path: the corrected trajectory of ~body_frame in "
                  "world_frame, e.g. VINS pose_graph_path, RTAB-Map mapPath) and move keyframes "
                  "to it");
  core::visitFlag(v, "correct_later_frames", correct_later_frames,
                  "with use_path_corrections: every frame after a path takes the path's "
                  "corrections as the keyframes do (after its last pose, the last one's), as "
                  "VINS' loop_fusion corrects the odometry that follows a loop closure. For a "
                  "pose source that is not corrected itself (VINS' /vins_estimator/odometry, an "
                  "odometry beside colmap_bridge's ~refined_path); leave it off for one that is "
                  "(RTAB-Map's tf map -> camera), which would be corrected twice");
  core::visitText(v, "odom_frame", odom_frame, {},
                  "with use_path_corrections and pose_source tf: the SLAM system's odometry "
                  "frame (RTAB-Map: odom) when its link to world_frame is the system's own loop "
                  "correction (map -> odom). Corrections are then measured against the camera's "
                  "poses in this frame, which a loop closure does not change: the frames looked "
                  "up after a loop closure, already corrected through map -> odom, are not "
                  "corrected again. Every frame needs odom_frame <- camera on tf too; \"\": "
                  "measured against the world_frame poses (a source that is never corrected "
                  "itself)");
  core::visitReal(v, "correction_max_source_gap", corrections.max_source_gap, 0.0, 10.0,
                  "a path pose gives a correction (path pose * the pose the node had at its "
                  "stamp^-1) when the node has poses of its frames on either side of its stamp "
                  "within this; each keyframe takes the correction interpolated at its stamp, "
                  "the nearest outside the path [s]");
  core::visitReal(v, "correction_min_translation", corrections.min_translation, 0.0, 1e6,
                  "a keyframe is moved (its row and column recomputed) when its centre moves "
                  "more than this [m] ...");
  core::visitReal(v, "correction_min_rotation_deg", corrections.min_rotation_deg, 0.0, 180.0,
                  "... or it turns more than this [deg]");
  v.section("Output");
  core::visitReal(v, "publish_period", publish_period, 0.0, 3600.0,
                  "~selection and ~markers at most this often, when changed [s, wall]");
  core::visitFlag(v, "save_keyframe_images", save_keyframe_images,
                  "keep keyframe images so that ~export writes them for COLMAP");
  core::visitReal(v, "marker_scale", marker_scale, 1e-6, 1e6,
                  "frustum depth in RViz [m, scene units]");
  core::visitInteger(v, "publish_max_views", publish_max_views, 0, 100000000,
                     "above this many keyframes ~selection carries only the views that changed "
                     "(at most this many a message) and ~markers every m-th view; 0 = always all");
  core::visitReal(v, "image_cache_mb", image_cache_mb, 0.0, 1e7,
                  "with save_keyframe_images: keyframe images kept in RAM [MB]; older ones are "
                  "written to image_dir and read back by ~export");
  core::visitText(v, "image_dir", image_dir, {},
                  "folder for keyframe images beyond image_cache_mb (a subfolder of the node's "
                  "own, removed on shutdown); \"\" = a temporary folder");
  v.section("State across restarts");
  core::visitText(v, "state_file", state_file, {},
                  "the session is saved here and continued from it at start (relative to "
                  "ROS_HOME, default ~/.ros; beside it: .journal, .registration, .previous); "
                  "\"\" = off");
  core::visitInteger(v, "autosave_keyframes", autosave_keyframes, 0, 1000000,
                     "save the session every N new keyframes (also on shutdown and ~save_state); "
                     "0 = only then");
  v.section("Pair stream (~pairs, ~get_pairs) and live hand-off (colmap_bridge)");
  core::visitInteger(v, "pair_stable_keyframes", pair_stable_keyframes, 0, 1000,
                     "a selected pair is announced on ~pairs once it is still selected this many "
                     "keyframes later (0: at once); pairs that go before cost a consumer nothing "
                     "(docs/live.md has the measured waste)");
  core::visitReal(v, "pair_flush_idle", pair_flush_idle, 0.0, 3600.0,
                  "when no frame arrived for this long (the recording paused or ended), every "
                  "selected pair is announced at once [s, wall]; 0 = never");
  core::visitInteger(v, "pair_history", pair_history, 1, 1000000,
                     "~pairs messages kept for ~get_pairs; a consumer further behind gets the "
                     "whole announced set");
  core::visitText(v, "keyframe_image_dir", keyframe_image_dir, {},
                  "each keyframe's image is written into this folder as it is accepted, named as "
                  "in selection.json, once (colmap_bridge sets it with ~write_keyframe_images); "
                  "\"\" = off");
  selector.visitParameters(v);
  point_params.visitParameters(v);
}

namespace {

/// Reads each listed parameter that is set, with the messages a user sees in the log.
class RosParamReader : public core::ParameterVisitor {
 public:
  explicit RosParamReader(const ros::NodeHandle& nh) : nh_(nh) {}

  void visit(const core::ParameterInfo& i, int& value) override {
    read(i, value, "an integer");
    if (value < i.min || value > i.max) outOfRange(i, value);
  }
  void visit(const core::ParameterInfo& i, double& value) override {
    read(i, value, "a number");
    if (!std::isfinite(value) || value < i.min || value > i.max) outOfRange(i, value);
  }
  void visit(const core::ParameterInfo& i, bool& value) override {
    read(i, value, "true or false");
  }
  void visit(const core::ParameterInfo& i, std::string& value) override {
    read(i, value, "a string");
    if (i.choices.empty() ||
        std::find(i.choices.begin(), i.choices.end(), value) != i.choices.end())
      return;
    std::string list;
    for (const auto& c : i.choices) list += (list.empty() ? "" : ", ") + c;
    throw core::InvalidArgument("parameter " + nh_.resolveName(i.name) + " = '" + value +
                                "' is not one of: " + list);
  }

 private:
  template <typename T>
  void read(const core::ParameterInfo& i, T& value, const char* type) {
    if (nh_.hasParam(i.name) && !nh_.getParam(i.name, value))
      throw core::InvalidArgument("parameter " + nh_.resolveName(i.name) + " must be " + type);
  }
  [[noreturn]] void outOfRange(const core::ParameterInfo& i, double value) {
    std::ostringstream s;
    s << "parameter " << nh_.resolveName(i.name) << " = " << value << " is out of range [" << i.min
      << ", " << i.max << "]";
    throw core::InvalidArgument(s.str());
  }

  const ros::NodeHandle& nh_;
};

struct NameCollector : core::ParameterVisitor {
  std::set<std::string> names;
  void visit(const core::ParameterInfo& i, int&) override { names.insert(i.name); }
  void visit(const core::ParameterInfo& i, double&) override { names.insert(i.name); }
  void visit(const core::ParameterInfo& i, bool&) override { names.insert(i.name); }
  void visit(const core::ParameterInfo& i, std::string&) override { names.insert(i.name); }
};

}  // namespace

std::string normaliseFrameId(const std::string& frame_id) {
  const size_t first = frame_id.find_first_not_of('/');
  return first == std::string::npos ? std::string() : frame_id.substr(first);
}

NodeConfig loadNodeConfig(const ros::NodeHandle& nh) {
  NodeConfig c;
  RosParamReader reader(nh);
  c.visitParameters(reader);
  c.world_frame = normaliseFrameId(c.world_frame);
  if (c.world_frame.empty())
    throw core::InvalidArgument("parameter " + nh.resolveName("world_frame") +
                                " must name a frame");
  c.camera_frame = normaliseFrameId(c.camera_frame);
  c.body_frame = normaliseFrameId(c.body_frame);
  c.odom_frame = normaliseFrameId(c.odom_frame);
  // As select_views: auto is depth when there is depth, features otherwise.
  if (c.point_source == "auto") c.point_source = c.use_depth ? "depth" : "features";
  if (c.point_source == "depth" && !c.use_depth)
    throw core::InvalidArgument("parameter " + nh.resolveName("point_source") +
                                " = depth needs depth images, but ~use_depth is false");
  c.point_params.validate();
  c.selector.validate();
  return c;
}

std::vector<std::string> unknownParameters(const ros::NodeHandle& nh) {
  NameCollector known;
  NodeConfig().visitParameters(known);
  std::vector<std::string> all, unknown;
  if (!ros::param::getParamNames(all)) return unknown;
  const std::string prefix = nh.getNamespace() + "/";
  for (const std::string& name : all) {
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string local = name.substr(prefix.size());
    if (local.empty() || local.find('/') != std::string::npos) continue;
    if (!known.names.count(local)) unknown.push_back(local);
  }
  std::sort(unknown.begin(), unknown.end());
  return unknown;
}

}  // namespace view_selection::ros_node
