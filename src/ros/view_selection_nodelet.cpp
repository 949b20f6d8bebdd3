// view_selection/ViewSelectionNodelet: the same ViewSelectionRos class inside a nodelet manager,
// so images from a camera driver nodelet arrive without serialisation.
#include "view_selection/ros/view_selection_ros.h"

#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include <memory>

namespace view_selection::ros_node {

class ViewSelectionNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      impl_ = std::make_unique<ViewSelectionRos>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::exception& e) {
      // Shutting the manager down would take its other nodelets with it: stay inert and say why.
      NODELET_FATAL("view_selection nodelet not started: %s", e.what());
    }
  }
  std::unique_ptr<ViewSelectionRos> impl_;
};

}  // namespace view_selection::ros_node

PLUGINLIB_EXPORT_CLASS(view_selection::ros_node::ViewSelectionNodelet, nodelet::Nodelet)
