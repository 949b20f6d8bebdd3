// Parameter reading through a real parameter server: defaults, every select_views option, frame
// normalisation, and a clear InvalidArgument for each kind of bad value.
#include "view_selection/core/exceptions.h"
#include "view_selection/ros/node_config.h"

#include <gtest/gtest.h>
#include <ros/ros.h>

#include <string>
#include <vector>

using namespace view_selection;
using namespace view_selection::ros_node;

namespace {

ros::NodeHandle fresh(const std::string& name) {
  ros::NodeHandle nh("/" + name);
  nh.deleteParam("");
  return nh;
}

std::string errorOf(const ros::NodeHandle& nh) {
  try {
    loadNodeConfig(nh);
  } catch (const core::InvalidArgument& e) {
    return e.what();
  }
  return "";
}

TEST(NodeConfig, DefaultsAreTheCoresAndTheDocumentedOnes) {
  const NodeConfig c = loadNodeConfig(fresh("defaults"));
  const core::ViewSelectorConfig defaults;
  EXPECT_EQ(c.world_frame, "world");
  EXPECT_EQ(c.camera_frame, "");
  EXPECT_EQ(c.pose_source, PoseSource::kTf);
  EXPECT_DOUBLE_EQ(c.pose_timeout, 0.5);
  EXPECT_EQ(c.queue_size, 90);  // 3 s at 30 Hz, as ~sync_unmatched_timeout (stop 26)
  EXPECT_DOUBLE_EQ(c.sync_timeout, 1.0);
  EXPECT_DOUBLE_EQ(c.sync_unmatched_timeout, 3.0);
  EXPECT_TRUE(c.use_depth);
  EXPECT_EQ(c.point_source, "depth");
  EXPECT_DOUBLE_EQ(c.publish_period, 0.5);
  EXPECT_FALSE(c.save_keyframe_images);
  EXPECT_EQ(c.selector.keyframes.mode, core::KeyframeMode::kScaleFree);  // issue 20
  EXPECT_DOUBLE_EQ(c.selector.keyframes.keyframe_overlap, defaults.keyframes.keyframe_overlap);
  EXPECT_DOUBLE_EQ(c.selector.keyframes.keyframe_parallax_deg,
                   defaults.keyframes.keyframe_parallax_deg);
  EXPECT_EQ(c.selector.keyframes.every_n, defaults.keyframes.every_n);
  EXPECT_DOUBLE_EQ(c.selector.keyframes.min_translation, defaults.keyframes.min_translation);
  EXPECT_DOUBLE_EQ(c.selector.keyframes.min_rotation_deg, defaults.keyframes.min_rotation_deg);
  EXPECT_EQ(c.selector.selection.k, defaults.selection.k);
  EXPECT_EQ(c.selector.selection.completion, core::CompletionMode::kReachable);  // by measurement
  EXPECT_EQ(c.selector.matrix.gate, core::Gate::kMatchable);
  EXPECT_EQ(c.selector.matrix.min_covisible_points, defaults.matrix.min_covisible_points);
  EXPECT_DOUBLE_EQ(c.selector.matrix.min_covisible_ratio, defaults.matrix.min_covisible_ratio);
  EXPECT_DOUBLE_EQ(c.selector.matrix.max_view_angle_deg, 0.0);
  EXPECT_TRUE(c.selector.matrix.occlusion.enabled);
  EXPECT_EQ(c.point_params.depth.grid, points::DepthSamplerConfig{}.grid);
}

TEST(NodeConfig, EveryOptionArrives) {
  ros::NodeHandle nh = fresh("options");
  nh.setParam("world_frame", "//map");
  nh.setParam("camera_frame", "/openni_rgb_optical_frame");
  nh.setParam("pose_source", "topic");
  nh.setParam("keyframe_policy", "every_nth");
  nh.setParam("every_n", 7);
  nh.setParam("min_translation", 1);  // an integer where a real is expected is fine
  nh.setParam("min_rotation_deg", 5.5);
  nh.setParam("k", 4);
  nh.setParam("completion", "reachable");
  nh.setParam("min_covisible_points", 20);
  nh.setParam("min_covisible_ratio", 0.25);
  nh.setParam("max_view_angle_deg", 60.0);
  nh.setParam("occlusion_test", false);
  nh.setParam("grid", 8);
  nh.setParam("point_source", "depth");
  const NodeConfig c = loadNodeConfig(nh);
  EXPECT_EQ(c.world_frame, "map");
  EXPECT_EQ(c.camera_frame, "openni_rgb_optical_frame");
  EXPECT_EQ(c.pose_source, PoseSource::kTopic);
  EXPECT_EQ(c.selector.keyframes.mode, core::KeyframeMode::kEveryNth);
  EXPECT_EQ(c.selector.keyframes.every_n, 7);
  EXPECT_DOUBLE_EQ(c.selector.keyframes.min_translation, 1.0);
  EXPECT_DOUBLE_EQ(c.selector.keyframes.min_rotation_deg, 5.5);
  EXPECT_EQ(c.selector.selection.k, 4);
  EXPECT_EQ(c.selector.selection.completion, core::CompletionMode::kReachable);
  EXPECT_EQ(c.selector.matrix.min_covisible_points, 20);
  EXPECT_DOUBLE_EQ(c.selector.matrix.min_covisible_ratio, 0.25);
  EXPECT_DOUBLE_EQ(c.selector.matrix.max_view_angle_deg, 60.0);
  EXPECT_FALSE(c.selector.matrix.occlusion.enabled);
  EXPECT_EQ(c.point_params.depth.grid, 8);  // one value: grid x grid cells
}

TEST(NodeConfig, BadValuesNameTheParameter) {
  struct Case {
    const char* name;
    XmlRpc::XmlRpcValue value;
    const char* expect;  // part of the message
  };
  const Case cases[] = {
      {"k", XmlRpc::XmlRpcValue(0), "/bad/k = 0 is out of range [1, 1000]"},
      {"k", XmlRpc::XmlRpcValue("five"), "/bad/k must be an integer"},
      {"min_covisible_ratio", XmlRpc::XmlRpcValue(1.5),
       "/bad/min_covisible_ratio = 1.5 is out of range"},
      {"pose_timeout", XmlRpc::XmlRpcValue(-1.0), "/bad/pose_timeout"},
      {"completion", XmlRpc::XmlRpcValue("best"), "is not one of: paper, reachable"},
      {"keyframe_policy", XmlRpc::XmlRpcValue("sometimes"),
       "is not one of: scale_free, every_frame, every_nth, motion, external"},
      {"pose_source", XmlRpc::XmlRpcValue("gps"), "is not one of: tf, topic, odometry, pose_with_covariance"},
      {"occlusion_test", XmlRpc::XmlRpcValue("yes"), "must be true or false"},
      {"world_frame", XmlRpc::XmlRpcValue("/"), "must name a frame"},
      {"point_source", XmlRpc::XmlRpcValue("lidar"), "is not one of: auto, depth, features, map"},
      {"features", XmlRpc::XmlRpcValue("surf"), "is not one of: orb, sift"},
      {"grid", XmlRpc::XmlRpcValue(0), "/bad/grid = 0 is out of range"},
  };
  for (const Case& c : cases) {
    ros::NodeHandle nh = fresh("bad");
    nh.setParam(c.name, c.value);
    const std::string message = errorOf(nh);
    EXPECT_NE(message.find(c.expect), std::string::npos) << c.name << ": '" << message << "'";
  }
  ros::NodeHandle nh = fresh("bad");
  nh.setParam("use_depth", false);
  nh.setParam("point_source", "depth");
  EXPECT_NE(errorOf(nh).find("~use_depth is false"), std::string::npos) << errorOf(nh);
}

TEST(NodeConfig, PointSources) {
  ros::NodeHandle nh = fresh("sources");
  EXPECT_EQ(loadNodeConfig(nh).point_source, "depth");  // auto with depth
  nh.setParam("use_depth", false);
  EXPECT_EQ(loadNodeConfig(nh).point_source, "features");  // auto without depth, as select_views
  nh.setParam("point_source", "map");
  nh.setParam("map_max_points", 500);
  const NodeConfig map = loadNodeConfig(nh);
  EXPECT_EQ(map.point_source, "map");
  EXPECT_EQ(map.point_params.map.max_points, 500);
  nh.setParam("point_source", "features");
  nh.setParam("features", "sift");
  nh.setParam("grid", 12);
  const NodeConfig features = loadNodeConfig(nh);
  EXPECT_EQ(features.point_params.features.detector, "sift");
  EXPECT_EQ(features.point_params.depth.grid, 12);
}

TEST(NodeConfig, MisspelledParametersAreNamed) {
  ros::NodeHandle nh = fresh("misspelled");
  nh.setParam("k", 3);
  nh.setParam("min_covisble_ratio", 0.5);        // misspelled
  nh.setParam("completoin", "reachable");        // misspelled
  nh.setParam("image/compressed/mode", 1);  // another component's namespace: not judged
  EXPECT_EQ(unknownParameters(nh), (std::vector<std::string>{"completoin", "min_covisble_ratio"}));
  EXPECT_EQ(loadNodeConfig(nh).selector.selection.k, 3);  // the known ones still arrive
  EXPECT_TRUE(unknownParameters(fresh("clean")).empty());
}

TEST(NodeConfig, NormaliseFrameId) {
  EXPECT_EQ(normaliseFrameId("/world"), "world");
  EXPECT_EQ(normaliseFrameId("//a/b"), "a/b");
  EXPECT_EQ(normaliseFrameId("camera"), "camera");
  EXPECT_EQ(normaliseFrameId("/"), "");
  EXPECT_EQ(normaliseFrameId(""), "");
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_node_config");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
