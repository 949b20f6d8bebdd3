#include "view_selection/ros/view_selection_ros.h"

namespace view_selection::ros_node {

namespace {

NodeConfig loadAndCheck(const ros::NodeHandle& private_nh) {
  NodeConfig config = loadNodeConfig(private_nh);
  for (const std::string& name : unknownParameters(private_nh))
    ROS_WARN_STREAM(
        "view_selection: unknown parameter "
        << private_nh.resolveName(name)
        << " is ignored (misspelled? every parameter is in config/view_selection.yaml)");
  if (config.use_path_corrections && config.point_source == "features")
    ROS_WARN(
        "view_selection: ~use_path_corrections with ~point_source features: corrected "
        "keyframes keep their triangulated points (moved with them), but later keyframes "
        "are triangulated against the feature tracks' uncorrected poses");
  if (config.correct_later_frames && !config.use_path_corrections)
    ROS_WARN(
        "view_selection: ~correct_later_frames without ~use_path_corrections: no path is read, "
        "so no frame is corrected");
  if (!config.odom_frame.empty() && config.correctionFrame().empty())
    ROS_WARN(
        "view_selection: ~odom_frame is ignored: it is read with ~use_path_corrections and "
        "~pose_source tf only");
  return config;
}

ros::NodeHandle withQueue(ros::NodeHandle nh, ros::CallbackQueue& queue) {
  nh.setCallbackQueue(&queue);
  return nh;
}

}  // namespace

ViewSelectionRos::ViewSelectionRos(ros::NodeHandle nh, ros::NodeHandle private_nh,
                                   const PointSourceFactory& make_points)
    : config_(loadAndCheck(private_nh)),
      keeper_(config_, statistics_, "view_selection_node " + private_nh.getNamespace()),
      poses_(makePoseProvider(config_, nh)),
      verdicts_(config_, nh),
      pairs_(config_, private_nh),
      worker_(config_, *poses_, statistics_, keeper_, &verdicts_, make_points, &pairs_,
              &image_writer_),
      outputs_(config_, nh, private_nh, worker_, statistics_),
      services_(config_, private_nh, worker_, *poses_, keeper_, pairs_, image_writer_,
                [this] { outputs_.update(); }),
      reconfigure_(config_, withQueue(private_nh, services_.queue()), worker_, outputs_),
      corrections_(config_, nh, worker_, *poses_, statistics_),
      inputs_(config_, nh, private_nh, worker_, statistics_) {
  if (!config_.keyframe_image_dir.empty()) {
    const std::string error = image_writer_.setDirectory(config_.keyframe_image_dir).error;
    if (!error.empty())
      ROS_ERROR_STREAM("view_selection: ~keyframe_image_dir: " << error
                                                               << "; keyframe images are not written");
  }
  const auto& s = config_.selector;
  ROS_INFO_STREAM("view_selection_node: "
                  << (config_.use_depth ? "image + camera_info + depth" : "image + camera_info")
                  << " from '" << nh.resolveName("image") << "', poses from " << poses_->describe()
                  << ", points from " << config_.point_source
                  << (config_.point_source == "map" ? " ('" + nh.resolveName("points") + "')"
                                                    : std::string())
                  << ", keyframes " << core::describeKeyframeRule(s.keyframes) << ", k " << s.selection.k
                  << ", completion " << core::toString(s.selection.completion)
                  << (keeper_.enabled() ? ", session saved in " + keeper_.path()
                                        : std::string(", session not saved (~state_file empty)")));
}

}  // namespace view_selection::ros_node
