#include "view_selection/ros/live_reconfigure.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/core/parameters.h"

namespace view_selection::ros_node {

namespace {

/// Applies `f` to each pair of (reconfigure field, config field) of the same name.
template <typename Values, typename Config, typename F>
void forEachField(Values& r, Config& c, F f) {
  auto& m = c.selector.matrix;
  auto& kf = c.selector.keyframes;
  f(r.k, c.selector.selection.k);
  f(r.max_parallax_deg, m.max_parallax_deg);
  f(r.max_scale_ratio, m.max_scale_ratio);
  f(r.min_covisible_points, m.min_covisible_points);
  f(r.min_covisible_ratio, m.min_covisible_ratio);
  f(r.max_view_angle_deg, m.max_view_angle_deg);
  f(r.every_n, kf.every_n);
  f(r.min_translation, kf.min_translation);
  f(r.min_rotation_deg, kf.min_rotation_deg);
  f(r.keyframe_overlap, kf.keyframe_overlap);
  f(r.keyframe_parallax_deg, kf.keyframe_parallax_deg);
  f(r.publish_period, c.publish_period);
}

}  // namespace

view_selection::ViewSelectionConfig toReconfigure(const NodeConfig& config) {
  view_selection::ViewSelectionConfig r = view_selection::ViewSelectionConfig::__getDefault__();
  NodeConfig c = config;
  forEachField(r, c, [](auto& to, auto& from) { to = from; });
  r.completion = core::toString(config.selector.selection.completion);
  r.keyframe_policy = core::toString(config.selector.keyframes.mode);
  r.gate = core::nameOf(config.selector.matrix.gate, core::kGateNames);
  return r;
}

void fromReconfigure(const view_selection::ViewSelectionConfig& values, NodeConfig& config) {
  view_selection::ViewSelectionConfig r = values;
  forEachField(r, config, [](auto& from, auto& to) { to = from; });
  config.selector.selection.completion = core::completionModeFromString(values.completion);
  config.selector.keyframes.mode = core::keyframeModeFromString(values.keyframe_policy);
  config.selector.matrix.gate = core::valueOf(values.gate, core::kGateNames, "gate");
}

LiveReconfigure::LiveReconfigure(const NodeConfig& config, ros::NodeHandle private_nh,
                                 KeyframeWorker& worker, SelectionOutputs& outputs)
    : current_(config), worker_(worker), outputs_(outputs), server_(mutex_, private_nh) {
  // Start from the values in force, not from the .cfg defaults.
  server_.updateConfig(toReconfigure(current_));
  server_.setCallback(
      [this](view_selection::ViewSelectionConfig& v, uint32_t level) { onChange(v, level); });
}

void LiveReconfigure::onChange(view_selection::ViewSelectionConfig& values, uint32_t level) {
  NodeConfig next = current_;
  try {
    fromReconfigure(values, next);
    next.selector.validate();
    const bool was_external = current_.selector.keyframes.mode == core::KeyframeMode::kExternal;
    if ((next.selector.keyframes.mode == core::KeyframeMode::kExternal) != was_external)
      throw core::InvalidArgument(
          "keyframe_policy external is chosen at start-up (it subscribes to `keyframes`)");
  } catch (const core::InvalidArgument& e) {
    ROS_WARN_STREAM("view_selection: reconfigure refused: " << e.what());
    values = toReconfigure(current_);
    return;
  }
  if (core::paramsOf(next.selector) != core::paramsOf(current_.selector)) {
    worker_.reconfigure(next.selector);
    ROS_INFO_STREAM("view_selection: reconfigured (level "
                    << level << "): k " << next.selector.selection.k << ", completion "
                    << core::toString(next.selector.selection.completion) << ", keyframes "
                    << core::toString(next.selector.keyframes.mode));
  }
  if (next.publish_period != current_.publish_period)
    outputs_.setPublishPeriod(next.publish_period);
  current_ = next;
}

}  // namespace view_selection::ros_node
