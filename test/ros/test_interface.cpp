// Interface rostest: the node (or nodelet) named by ~node advertises its topics and its seven
// services, subscribes to its inputs, and an empty node answers every service sensibly. The node
// started as the README starts it (rosrun, no name given) serves under /view_selection.
#include <view_selection/Export.h>
#include <view_selection/GetNextViews.h>
#include <view_selection/GetPairs.h>
#include <view_selection/GetSelection.h>
#include <view_selection/WriteKeyframeImages.h>
#include <view_selection/InputStatistics.h>
#include <view_selection/ViewSelection.h>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>
#include <algorithm>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace {

std::string nodeName() {
  std::string name = "/view_selection";
  ros::NodeHandle("~").getParam("node", name);
  return name;
}

template <typename Srv>
bool call(const std::string& name, Srv& srv) {
  if (!ros::service::waitForService(name, ros::Duration(20.0))) return false;
  return ros::service::call(name, srv);
}

// Names of topics with at least one subscriber / publisher, from the master; false when the
// master does not answer.
[[nodiscard]] bool systemState(std::vector<std::string>& published,
                               std::vector<std::string>& subscribed) {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  if (!ros::master::execute("getSystemState", args, result, payload, true)) return false;
  for (int kind = 0; kind < 2; ++kind) {
    auto& out = kind == 0 ? published : subscribed;
    for (int i = 0; i < payload[kind].size(); ++i)
      out.push_back(static_cast<std::string>(payload[kind][i][0]));
  }
  return true;
}

bool contains(const std::vector<std::string>& list, const std::string& item) {
  return std::find(list.begin(), list.end(), item) != list.end();
}

TEST(Interface, AdvertisesTopicsAndSubscribesToInputs) {
  const std::string node = nodeName();
  ASSERT_TRUE(ros::service::waitForService(node + "/get_selection", ros::Duration(20.0)))
      << node << " did not come up";
  std::vector<std::string> published, subscribed;
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  // The subscriptions are made right after the services; give them a moment.
  do {
    published.clear();
    subscribed.clear();
    ASSERT_TRUE(systemState(published, subscribed)) << "the master did not answer getSystemState";
    if (contains(subscribed, "/camera/depth") && contains(published, node + "/statistics")) break;
    ros::WallDuration(0.1).sleep();
  } while (ros::WallTime::now() < deadline);
  for (const char* topic : {"/selection", "/markers", "/statistics"})
    EXPECT_TRUE(contains(published, node + topic)) << node + topic << " is not advertised";
  // The launch file remaps image/camera_info/depth under /camera.
  for (const char* topic : {"/camera/image", "/camera/camera_info", "/camera/depth"})
    EXPECT_TRUE(contains(subscribed, topic)) << topic << " has no subscriber";
  EXPECT_TRUE(contains(published, node + "/pairs")) << node << "/pairs is not advertised";
  for (const char* srv : {"/get_next_views", "/get_selection", "/export", "/reset", "/get_pairs",
                          "/write_keyframe_images", "/save_state"})
    EXPECT_TRUE(ros::service::exists(node + srv, false)) << node + srv << " is not advertised";
}

TEST(Interface, EmptyNodeAnswersSensibly) {
  const std::string node = nodeName();
  view_selection::GetSelection selection;
  ASSERT_TRUE(call(node + "/get_selection", selection));
  EXPECT_TRUE(selection.response.success) << selection.response.message;
  EXPECT_TRUE(selection.response.selection.keyframes.empty());
  EXPECT_EQ(selection.response.selection.start_view, -1);
  EXPECT_TRUE(selection.response.selection.pairs.empty());
  EXPECT_EQ(selection.response.selection.k, 3);  // ~k from the launch file, not the default 5
  EXPECT_EQ(selection.response.selection.completion, "reachable");
  EXPECT_EQ(selection.response.selection.header.frame_id, "map");  // "/map" normalised

  // The latched topic carries the same empty selection.
  ros::NodeHandle nh;
  view_selection::ViewSelection::ConstPtr latched =
      ros::topic::waitForMessage<view_selection::ViewSelection>(node + "/selection", nh,
                                                                ros::Duration(10.0));
  ASSERT_TRUE(latched) << "no latched message on " << node << "/selection";
  EXPECT_TRUE(latched->keyframes.empty());
  view_selection::InputStatistics::ConstPtr stats =
      ros::topic::waitForMessage<view_selection::InputStatistics>(node + "/statistics", nh,
                                                                  ros::Duration(10.0));
  ASSERT_TRUE(stats) << "no latched message on " << node << "/statistics";
  EXPECT_EQ(stats->keyframes, 0u);
  EXPECT_EQ(stats->frames_dropped, 0u);

  view_selection::Export exp;
  // A folder of this test's own (the node name has a '/'; keep it one path component).
  std::string own = node;
  std::replace(own.begin(), own.end(), '/', '_');
  exp.request.directory = (std::filesystem::temp_directory_path() /
                           ("view_selection_test_" + std::to_string(::getpid()) + own))
                              .string();
  ASSERT_TRUE(call(node + "/export", exp));
  EXPECT_TRUE(exp.response.success) << exp.response.message;
  std::ifstream pairs(exp.response.pairs_txt);
  EXPECT_TRUE(pairs.good()) << exp.response.pairs_txt << " was not written";
  std::ifstream json(exp.response.selection_json);
  EXPECT_TRUE(json.good()) << exp.response.selection_json << " was not written";
  std::error_code ec;
  std::filesystem::remove_all(exp.request.directory, ec);

  // The pair stream from the start: one full message of the (empty) announced set.
  view_selection::GetPairs pairs_srv;
  pairs_srv.request.since = 0;
  ASSERT_TRUE(call(node + "/get_pairs", pairs_srv));
  EXPECT_TRUE(pairs_srv.response.success) << pairs_srv.response.message;
  ASSERT_EQ(pairs_srv.response.changes.size(), 1u);
  EXPECT_TRUE(pairs_srv.response.changes[0].full);
  EXPECT_TRUE(pairs_srv.response.changes[0].added.empty());
  EXPECT_EQ(pairs_srv.response.keyframe_image_dir, "");
  EXPECT_TRUE(pairs_srv.response.keyframe_images_lost.empty());

  // Keyframe images into a folder: none yet, so nothing written, queued, dropped or missing;
  // ~get_pairs names the folder; "" stops; a folder that cannot be made is an error.
  view_selection::WriteKeyframeImages images;
  images.request.directory = exp.request.directory + "_images";
  ASSERT_TRUE(call(node + "/write_keyframe_images", images));
  EXPECT_TRUE(images.response.success) << images.response.message;
  EXPECT_EQ(images.response.images_written + images.response.images_queued +
                images.response.images_dropped + images.response.images_missing,
            0);
  ASSERT_TRUE(call(node + "/get_pairs", pairs_srv));
  EXPECT_EQ(pairs_srv.response.keyframe_image_dir, images.request.directory);
  images.request.directory = "";
  ASSERT_TRUE(call(node + "/write_keyframe_images", images));
  EXPECT_TRUE(images.response.success) << images.response.message;
  ASSERT_TRUE(call(node + "/get_pairs", pairs_srv));
  EXPECT_EQ(pairs_srv.response.keyframe_image_dir, "");
  images.request.directory = "/proc/version/cannot_be_a_folder";
  ASSERT_TRUE(call(node + "/write_keyframe_images", images));
  EXPECT_FALSE(images.response.success);
  EXPECT_NE(images.response.message.find("cannot make folder"), std::string::npos)
      << images.response.message;
  std::filesystem::remove_all(exp.request.directory + "_images", ec);

  // Without ~state_file (both launch files here), saving is off, and says so.
  std_srvs::Trigger save;
  ASSERT_TRUE(call(node + "/save_state", save));
  EXPECT_FALSE(save.response.success);
  EXPECT_NE(save.response.message.find("state_file"), std::string::npos) << save.response.message;

  std_srvs::Trigger reset;
  ASSERT_TRUE(call(node + "/reset", reset));
  EXPECT_TRUE(reset.response.success) << reset.response.message;
}

// The README's `rosrun view_selection view_selection_node image:=...` gives no name: the node
// must still serve where the README's rosservice calls look, /view_selection/... (here under a
// namespace of its own, beside the node the launch file started).
TEST(Interface, RosrunWithoutANameServesUnderViewSelection) {
  if (nodeName() != "/view_selection") GTEST_SKIP() << "checked once, in interface.test";
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::setpgid(0, 0);
    ::execlp("rosrun", "rosrun", "view_selection", "view_selection_node", "__ns:=/readme",
             "image:=/readme/camera/image", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const bool up = ros::service::waitForService("/readme/view_selection/get_selection",
                                               ros::Duration(60.0));
  view_selection::GetSelection selection;
  const bool answered = up && ros::service::call("/readme/view_selection/get_selection", selection);
  ::kill(-pid, SIGINT);
  int status = 0;
  for (int i = 0; i < 150 && ::waitpid(pid, &status, WNOHANG) == 0; ++i)
    ros::WallDuration(0.1).sleep();
  if (::waitpid(pid, &status, WNOHANG) == 0) {
    ::kill(-pid, SIGKILL);
    ::waitpid(pid, &status, 0);
  }
  ASSERT_TRUE(up) << "rosrun view_selection view_selection_node does not serve "
                     "/readme/view_selection/get_selection";
  EXPECT_TRUE(answered && selection.response.success);
}

TEST(Interface, PublishesDiagnostics) {
  const std::string node = nodeName();
  ros::NodeHandle nh;
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(15.0);
  while (ros::WallTime::now() < deadline) {
    const auto array = ros::topic::waitForMessage<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", nh, ros::Duration(5.0));
    if (!array) continue;
    for (const auto& status : array->status) {
      if (status.name.find("view selection") == std::string::npos) continue;
      std::map<std::string, std::string> values;
      for (const auto& kv : status.values) values[kv.key] = kv.value;
      for (const char* key : {"input rate [frames/s]", "frames received", "frames dropped",
                              "worker lag [s]", "keyframes", "last insertion [s]"})
        EXPECT_TRUE(values.count(key)) << "no '" << key << "' in the diagnostics of " << node;
      EXPECT_EQ(values["keyframes"], "0");
      EXPECT_EQ(status.level, diagnostic_msgs::DiagnosticStatus::OK) << status.message;
      return;
    }
  }
  ADD_FAILURE() << "no 'view selection' status on /diagnostics within 15 s";
}

TEST(Interface, ReconfigureChangesTheSelectionLive) {
  const std::string node = nodeName();
  dynamic_reconfigure::Reconfigure srv;
  dynamic_reconfigure::IntParameter k;
  k.name = "k";
  k.value = 2;
  srv.request.config.ints.push_back(k);
  dynamic_reconfigure::StrParameter completion;
  completion.name = "completion";
  completion.value = "paper";
  srv.request.config.strs.push_back(completion);
  ASSERT_TRUE(call(node + "/set_parameters", srv));
  view_selection::GetSelection selection;
  ASSERT_TRUE(call(node + "/get_selection", selection));
  EXPECT_EQ(selection.response.selection.k, 2);
  EXPECT_EQ(selection.response.selection.completion, "paper");
  // Back to the launch file's values, for the other tests.
  srv.request.config.ints[0].value = 3;
  srv.request.config.strs[0].value = "reachable";
  ASSERT_TRUE(call(node + "/set_parameters", srv));
  ASSERT_TRUE(call(node + "/get_selection", selection));
  EXPECT_EQ(selection.response.selection.k, 3);
}

TEST(Interface, UnknownViewIsAnErrorWithAMessage) {
  const std::string node = nodeName();
  for (const int view : {0, 7, -1}) {
    view_selection::GetNextViews srv;
    srv.request.view = view;
    srv.request.after_completion = view == 7;
    ASSERT_TRUE(call(node + "/get_next_views", srv));
    EXPECT_FALSE(srv.response.success) << "view " << view;
    EXPECT_NE(srv.response.message.find("unknown"), std::string::npos) << srv.response.message;
    EXPECT_TRUE(srv.response.next_views.empty());
  }
}

TEST(Interface, ExportWithoutDirectoryIsAnError) {
  const std::string node = nodeName();
  view_selection::Export exp;
  ASSERT_TRUE(call(node + "/export", exp));
  EXPECT_FALSE(exp.response.success);
  EXPECT_FALSE(exp.response.message.empty());
  // A path under a regular file cannot be created.
  exp.request.directory = "/proc/version/cannot_be_a_folder";
  ASSERT_TRUE(call(node + "/export", exp));
  EXPECT_FALSE(exp.response.success);
  EXPECT_NE(exp.response.message.find("cannot"), std::string::npos) << exp.response.message;
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_interface");
  ros::NodeHandle nh;
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
