// view_selection_node: the ViewSelectionRos class on a node of its own.
#include "view_selection/core/exceptions.h"
#include "view_selection/ros/node_main.h"
#include "view_selection/ros/view_selection_ros.h"

namespace {

// The node's default name is the one the launch files, the README and colmap_bridge use, so that
// `rosrun view_selection view_selection_node` serves /view_selection/... as documented.
constexpr const char* kUsage =
    R"(usage: rosrun view_selection view_selection_node image:=TOPIC camera_info:=TOPIC depth:=TOPIC [_param:=value ...]

Chooses keyframes from synchronised images, camera_info and depth, with poses from tf or a pose
topic, and keeps for each keyframe the views that resist matching error best (docs/node.md).
The node is named /view_selection unless __name:=NAME says otherwise; its topics and services are
under that name.

Subscribes (relative names: remap them)
  image, camera_info, depth     sensor_msgs/Image, CameraInfo, Image (16UC1 mm or 32FC1 m);
                                compressed topics with _image_transport:=compressed and
                                _depth_image_transport:=compressedDepth
  /tf or pose                   the camera pose (~pose_source: tf, topic, odometry,
                                pose_with_covariance)
  path, keyframes, points       loop-closure paths, external keyframes, map points (when enabled)
Publishes (private)
  ~selection ~markers ~statistics ~pairs, and /diagnostics
Services (private)
  ~get_next_views ~get_selection ~get_pairs ~export ~write_keyframe_images ~save_state ~reset

Every parameter, with its default and meaning:
  rosrun view_selection view_selection_params --yaml   (config/view_selection.yaml)
Beside a SLAM system or a camera driver:
  roslaunch view_selection view_selection.launch image:=... camera_info:=... depth:=...
  rosservice call /view_selection/get_next_views "{view: 3, after_completion: true}"
)";

}  // namespace

int main(int argc, char** argv) {
  using namespace view_selection::ros_node;
  return runNode<ViewSelectionRos>(argc, argv, "view_selection", "view_selection_node", kUsage);
}
