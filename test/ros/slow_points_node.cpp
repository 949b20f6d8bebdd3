// Test scaffolding (issue 21): view_selection_node whose point source takes ~slow_point_source_ms
// more per keyframe than the real one, and ~slow_point_source_stall_ms for its 10th keyframe
// (parameters of this test binary only), so that a burst of frames outruns the worker and one
// insertion lasts longer than roscpp's queue of 100 frames at 30 Hz. worker_behind.test runs it
// at the node's shipped defaults.
#include "view_selection/core/exceptions.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/ros/view_selection_ros.h"

#include <ros/ros.h>

#include <chrono>
#include <memory>
#include <thread>

namespace {

using view_selection::core::PointSource;

/// The real source, then a sleep: a point source as slow as triangulation with Ceres can be.
class SlowPointSource : public PointSource {
 public:
  SlowPointSource(std::unique_ptr<PointSource> inner, double seconds, double stall)
      : inner_(std::move(inner)), seconds_(seconds), stall_(stall) {}
  std::string name() const override { return inner_->name(); }
  view_selection::core::PointSourceResult process(view_selection::core::ViewId id,
                                                  const view_selection::core::Frame& frame) override {
    std::this_thread::sleep_for(std::chrono::duration<double>(++calls_ == 10 ? stall_ : seconds_));
    return inner_->process(id, frame);
  }
  void reset() override { inner_->reset(); }
  view_selection::core::Params params() const override { return inner_->params(); }

 private:
  std::unique_ptr<PointSource> inner_;
  double seconds_, stall_;
  int calls_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "slow_points_node");
  ros::NodeHandle nh, private_nh("~");
  double ms = 200.0, stall_ms = 4000.0;
  private_nh.param("slow_point_source_ms", ms, ms);
  private_nh.param("slow_point_source_stall_ms", stall_ms, stall_ms);
  // Not parameters of the node proper.
  private_nh.deleteParam("slow_point_source_ms");
  private_nh.deleteParam("slow_point_source_stall_ms");
  std::unique_ptr<view_selection::ros_node::ViewSelectionRos> node;
  try {
    node = std::make_unique<view_selection::ros_node::ViewSelectionRos>(
        nh, private_nh, [ms, stall_ms](const view_selection::ros_node::NodeConfig& config) {
          return std::make_unique<SlowPointSource>(
              view_selection::points::makePointSource(config.point_source, config.point_params,
                                                      config.selector.matrix.occlusion),
              ms / 1000.0, stall_ms / 1000.0);
        });
  } catch (const std::exception& e) {
    ROS_FATAL("slow_points_node: %s", e.what());
    return 1;
  }
  ros::spin();
  node.reset();
  return 0;
}
