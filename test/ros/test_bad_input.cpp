// Bad-input rostest: good frames interleaved with every kind of wrong input. The node must drop
// each bad frame for the right reason, stay up, keep answering, and end with exactly the good
// frames as keyframes, with the same matrix and selection as the core computes on them.
//
// Good frames come from ../shared/data/redkitchen-0-499 (relative to the source folder) when it
// is there, otherwise from a synthetic tilted wall seen by a camera moving sideways.
#include <view_selection/Export.h>
#include <view_selection/GetNextViews.h>
#include <view_selection/GetSelection.h>
#include <view_selection/InputStatistics.h>
#include <view_selection/ViewSelection.h>

#include "view_selection/core/pose_interpolation.h"
#include "view_selection/core/view_selector.h"
#include "view_selection/io/tum_dataset.h"
#include "view_selection/io/tum_frames.h"
#include "view_selection/points/depth_sampler.h"
#include "view_selection/ros/conversions.h"

#include <cv_bridge/cv_bridge.h>
#include <opencv2/imgcodecs.hpp>
#include "view_selection/images/image_conversion.h"
#include "view_selection/points/map_point_source.h"
#include "view_selection/points/point_source_factory.h"

#include "../support/real_data.h"

#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_srvs/Trigger.h>
#include <tf2_msgs/TFMessage.h>
#include <visualization_msgs/MarkerArray.h>
#include <boost/make_shared.hpp>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace view_selection;
using namespace view_selection::images;
using namespace view_selection::io;
using namespace view_selection::points;

namespace {

struct GoodFrame {
  ros::Time stamp;
  core::PinholeIntrinsics intrinsics;
  core::CameraPose pose;
  cv::Mat image;  // BGR
  cv::Mat depth;  // as published: CV_32FC1 metres or CV_16UC1 millimetres
};

std::vector<GoodFrame> realFrames(const std::string& folder, size_t count, size_t step) {
  const TumDataset dataset = loadTumDataset(folder);
  std::vector<GoodFrame> frames;
  for (size_t q = 0; q < count && q * step < dataset.frames.size(); ++q) {
    const core::Frame f = loadTumFrame(dataset, dataset.frames[q * step], {true, true});
    GoodFrame g;
    g.intrinsics = f.intrinsics;
    g.pose = f.pose;
    g.image = matOf(f.image).clone();
    g.depth = matOf(f.depth).clone();
    frames.push_back(g);
  }
  return frames;
}

// A wall z = 2 + 0.3 x (world) with a bump, seen by a camera moving along x, looking along +z.
std::vector<GoodFrame> syntheticFrames(size_t count) {
  std::vector<GoodFrame> frames;
  core::PinholeIntrinsics k;
  k.fx = k.fy = 150.0;
  k.cx = 80.0;
  k.cy = 60.0;
  k.width = 160;
  k.height = 120;
  for (size_t i = 0; i < count; ++i) {
    GoodFrame g;
    g.intrinsics = k;
    g.pose.position = {0.08 * static_cast<double>(i), 0.02 * std::sin(static_cast<double>(i)), 0.0};
    g.pose.orientation = Eigen::Quaterniond(
        Eigen::AngleAxisd(0.02 * static_cast<double>(i), Eigen::Vector3d::UnitY()));
    g.depth = cv::Mat(k.height, k.width, CV_32FC1);
    g.image = cv::Mat(k.height, k.width, CV_8UC3, cv::Scalar(90, 120, 150));
    const Eigen::Matrix3d R = g.pose.rotation();
    for (int v = 0; v < k.height; ++v)
      for (int u = 0; u < k.width; ++u) {
        const Eigen::Vector3d ray_cam = k.backProject({u + 0.5, v + 0.5});
        const Eigen::Vector3d d = R * ray_cam;
        const Eigen::Vector3d& o = g.pose.position;
        // o.z + t d.z = 2 + 0.3 (o.x + t d.x) + 0.1 sin(3 (o.y + t d.y)) ~ solve the plane part.
        const double t = (2.0 + 0.3 * o.x() - o.z()) / (d.z() - 0.3 * d.x());
        g.depth.at<float>(v, u) = static_cast<float>(t * (1.0 + 0.02 * std::sin(0.1 * u)));
      }
    frames.push_back(g);
  }
  return frames;
}

class BadInputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ros::NodeHandle pnh("~");
    pnh.param<std::string>("node", node_, "/view_selection");
    pnh.param<std::string>("pose_source", pose_source_, "tf");
    pnh.param<int>("k", k_, 5);
    pnh.param<std::string>("point_source", point_source_, "depth");
    points_pub_ = nh_.advertise<sensor_msgs::PointCloud2>("camera/points", 2, true);
    image_pub_ = nh_.advertise<sensor_msgs::Image>("camera/image", 50);
    info_pub_ = nh_.advertise<sensor_msgs::CameraInfo>("camera/camera_info", 50);
    depth_pub_ = nh_.advertise<sensor_msgs::Image>("camera/depth", 50);
    if (pose_source_ == "tf")
      tf_pub_ = nh_.advertise<tf2_msgs::TFMessage>("/tf", 50);
    else
      pose_pub_ = nh_.advertise<geometry_msgs::PoseStamped>("camera/pose", 50);
    stats_sub_ = nh_.subscribe(node_ + "/statistics", 10, &BadInputTest::onStatistics, this);
  }

  void onStatistics(const view_selection::InputStatistics::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    stats_ = msg;
  }
  view_selection::InputStatistics::ConstPtr stats() {
    std::lock_guard<std::mutex> lock(mutex_);
    return stats_;
  }
  uint64_t handled() {
    const auto s = stats();
    return s ? s->frames_offered + s->frames_dropped : 0;
  }

  bool waitForSubscribers() {
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(20.0);
    while (ros::WallTime::now() < deadline) {
      const bool poses = pose_source_ == "tf" ? tf_pub_.getNumSubscribers() > 0
                                              : pose_pub_.getNumSubscribers() > 0;
      if (image_pub_.getNumSubscribers() > 0 && info_pub_.getNumSubscribers() > 0 &&
          depth_pub_.getNumSubscribers() > 0 && poses && stats() &&
          (point_source_ != "map" || points_pub_.getNumSubscribers() > 0))
        return true;
      ros::WallDuration(0.05).sleep();
    }
    return false;
  }

  struct Send {
    ros::Time stamp;
    sensor_msgs::ImagePtr image, depth;
    sensor_msgs::CameraInfo info;
    std::string camera_frame;  // "" = no pose published at all
    core::CameraPose pose;
    std::string pose_frame = "world";
  };
  Send makeSend(const GoodFrame& g, const ros::Time& stamp, const std::string& camera) {
    Send s;
    s.stamp = stamp;
    std_msgs::Header h;
    h.stamp = stamp;
    h.frame_id = "/" + camera;  // leading '/' as in old bags: the node normalises it
    s.image = cv_bridge::CvImage(h, sensor_msgs::image_encodings::BGR8, g.image).toImageMsg();
    s.depth =
        cv_bridge::CvImage(h,
                           g.depth.type() == CV_16UC1 ? sensor_msgs::image_encodings::TYPE_16UC1
                                                      : sensor_msgs::image_encodings::TYPE_32FC1,
                           g.depth)
            .toImageMsg();
    s.info.header = h;
    s.info.width = static_cast<uint32_t>(g.intrinsics.width);
    s.info.height = static_cast<uint32_t>(g.intrinsics.height);
    s.info.K = {g.intrinsics.fx,
                0.0,
                g.intrinsics.cx,
                0.0,
                g.intrinsics.fy,
                g.intrinsics.cy,
                0.0,
                0.0,
                1.0};
    s.camera_frame = camera;
    s.pose = g.pose;
    return s;
  }
  /// Publishes one frame and waits (bounded) until the node has offered or dropped it. Returns a
  /// failure (for ASSERT_TRUE at the call site) when it did not within 10 s.
  [[nodiscard]] ::testing::AssertionResult publish(const Send& s, uint64_t expect_handled) {
    if (!s.camera_frame.empty()) {
      if (pose_source_ == "tf") {
        geometry_msgs::TransformStamped t;
        t.header.stamp = s.stamp;
        t.header.frame_id = "world";
        t.child_frame_id = s.camera_frame;
        t.transform = ros_node::transformToMsg(s.pose);
        tf2_msgs::TFMessage m;
        m.transforms.push_back(t);
        tf_pub_.publish(m);
      } else {
        geometry_msgs::PoseStamped p;
        p.header.stamp = s.stamp;
        p.header.frame_id = s.pose_frame;
        p.pose = ros_node::poseToMsg(s.pose);
        pose_pub_.publish(p);
      }
    }
    depth_pub_.publish(s.depth);
    info_pub_.publish(s.info);
    image_pub_.publish(s.image);
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
    while (handled() < expect_handled && ros::WallTime::now() < deadline)
      ros::WallDuration(0.01).sleep();
    if (handled() >= expect_handled) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure()
           << "the node did not handle the frame at " << s.stamp << " within 10 s";
  }

  ros::NodeHandle nh_;
  std::string node_, pose_source_, point_source_;
  int k_ = 5;
  ros::Publisher image_pub_, info_pub_, depth_pub_, tf_pub_, pose_pub_, points_pub_;
  ros::Subscriber stats_sub_;
  std::mutex mutex_;
  view_selection::InputStatistics::ConstPtr stats_;
};

TEST_F(BadInputTest, DropsEachBadFrameKeepsAnsweringAndKeepsExactlyTheGoodFrames) {
  if (point_source_ == "map") GTEST_SKIP() << "map_input.test runs MapPointsReplaceAndUpdateRows";
  bool synthetic = false;  // ~synthetic forces the built-in frames even when the data is there
  ros::NodeHandle("~").param("synthetic", synthetic, false);
  const auto data =
      synthetic ? std::nullopt
                : view_selection::test::realData(
                      "redkitchen-0-499", "BadInputTest (" + pose_source_ + "): synthetic frames");
  std::vector<GoodFrame> good = data ? realFrames(data->string(), 6, 15) : syntheticFrames(6);
  ASSERT_EQ(good.size(), 6u);
  // One good frame in 16UC1 millimetres, the other path the node reads.
  {
    cv::Mat mm(good[3].depth.size(), CV_16UC1);
    for (int v = 0; v < mm.rows; ++v)
      for (int u = 0; u < mm.cols; ++u)
        mm.at<uint16_t>(v, u) =
            static_cast<uint16_t>(std::lround(good[3].depth.at<float>(v, u) * 1000.0f));
    good[3].depth = mm;
  }
  ASSERT_TRUE(waitForSubscribers()) << "the node under test did not subscribe within 20 s";

  const double t0 = 1000.0;
  double t = t0;
  int camera = 0;
  uint64_t sent = 0;
  std::vector<GoodFrame> expected;
  std::vector<ros::Time> expected_stamps;
  std::map<std::string, uint64_t> expected_drops;
  auto next = [&](const GoodFrame& g) {
    t += 0.1;
    return makeSend(g, ros::Time(t), "cam_" + std::to_string(camera++));
  };
  auto sendGood = [&](size_t i) {
    Send s = next(good[i]);
    expected.push_back(good[i]);
    expected_stamps.push_back(s.stamp);
    return publish(s, ++sent);
  };
  auto sendBad = [&](Send s, const std::string& reason) {
    ++expected_drops[reason];
    return publish(s, ++sent);
  };

  ASSERT_TRUE(sendGood(0));
  {  // a depth-like encoding on the image topic
    Send s = next(good[1]);
    s.image->encoding = "32FC1";
    s.image->step = s.image->width * 4;
    s.image->data.resize(s.image->step * s.image->height);
    ASSERT_TRUE(sendBad(s, "bad_image"));
  }
  {  // an encoding nobody knows
    Send s = next(good[1]);
    s.image->encoding = "not_an_encoding";
    ASSERT_TRUE(sendBad(s, "bad_image"));
  }
  ASSERT_TRUE(sendGood(1));
  {  // an empty image
    Send s = next(good[2]);
    s.image->width = s.image->height = 0;
    s.image->step = 0;
    s.image->data.clear();
    ASSERT_TRUE(sendBad(s, "bad_image"));
  }
  {  // a truncated image
    Send s = next(good[2]);
    s.image->data.resize(s.image->data.size() / 2);
    ASSERT_TRUE(sendBad(s, "bad_image"));
  }
  {  // colour on the depth topic
    Send s = next(good[2]);
    s.depth = cv_bridge::CvImage(s.image->header, sensor_msgs::image_encodings::BGR8, good[2].image)
                  .toImageMsg();
    ASSERT_TRUE(sendBad(s, "bad_depth"));
  }
  {  // 32FC1 depth whose rows are not whole floats apart (found by fuzz_messages: OpenCV threw)
    Send s = next(good[2]);
    auto depth = boost::make_shared<sensor_msgs::Image>(*s.depth);
    depth->step = depth->width * 4 + 2;
    depth->data.assign(static_cast<size_t>(depth->step) * depth->height, 0);
    s.depth = depth;
    ASSERT_TRUE(sendBad(s, "bad_depth"));
  }
  ASSERT_TRUE(sendGood(2));
  {  // camera_info with zero focal length
    Send s = next(good[3]);
    s.info.K[0] = 0.0;
    s.info.K[4] = 0.0;
    ASSERT_TRUE(sendBad(s, "bad_camera_info"));
  }
  {  // a NaN pose (tf2 refuses it, so under tf the frame finds no pose)
    Send s = next(good[3]);
    s.pose.position.x() = std::numeric_limits<double>::quiet_NaN();
    ASSERT_TRUE(sendBad(s, pose_source_ == "tf" ? "no_pose" : "bad_pose"));
  }
  {  // an unknown frame: the image's frame has no transform / the pose is in another frame
    Send s = next(good[3]);
    if (pose_source_ == "tf")
      s.camera_frame.clear();  // nothing is published for it
    else
      s.pose_frame = "mars";
    ASSERT_TRUE(sendBad(s, pose_source_ == "tf" ? "no_pose" : "bad_pose"));
  }
  ASSERT_TRUE(sendGood(3));
  {  // the same stamp again
    Send s = makeSend(good[4], expected_stamps.back(), "cam_" + std::to_string(camera++));
    ASSERT_TRUE(sendBad(s, "duplicate_stamp"));
  }
  {  // a stamp before the last good one
    Send s = makeSend(good[4], expected_stamps[1] + ros::Duration(0.05),
                      "cam_" + std::to_string(camera++));
    ASSERT_TRUE(sendBad(s, "out_of_order_stamp"));
  }
  ASSERT_TRUE(sendGood(4));
  ASSERT_TRUE(sendGood(5));

  // The statistics name every reason with its count.
  const auto s = stats();
  ASSERT_TRUE(s);
  std::map<std::string, uint64_t> drops;
  for (size_t i = 0; i < s->drop_reasons.size(); ++i) drops[s->drop_reasons[i]] = s->drop_counts[i];
  EXPECT_EQ(drops, expected_drops);
  EXPECT_EQ(s->frames_received, sent);
  EXPECT_EQ(s->frames_offered, expected.size());
  EXPECT_FALSE(s->last_error.empty());

  // The node still answers, from the good frames only.
  view_selection::GetSelection srv;
  ASSERT_TRUE(ros::service::waitForService(node_ + "/get_selection", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call(node_ + "/get_selection", srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  const auto& sel = srv.response.selection;
  ASSERT_EQ(sel.keyframes.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i)
    EXPECT_EQ(sel.keyframes[i].stamp, expected_stamps[i]) << i;

  // The same frames through the core directly: the node's selection must equal it exactly.
  core::ViewSelectorConfig config;
  config.keyframes.mode = core::KeyframeMode::kEveryFrame;
  config.selection.k = k_;
  core::ViewSelector selector(config, makePointSource("depth"));
  for (size_t i = 0; i < expected.size(); ++i) {
    core::Frame f;
    f.stamp = expected_stamps[i].toSec();
    f.image_name = ros_node::keyframeImageName(f.stamp);
    f.intrinsics = expected[i].intrinsics;
    f.pose = expected[i].pose;
    f.depth = depthImageOf(images::depthToMetres(
        expected[i].depth, expected[i].depth.type() == CV_16UC1 ? 0.001 : 1.0));
    ASSERT_EQ(selector.addFrame(f).outcome, core::FrameOutcome::kKeyframe);
  }
  const core::Selection want = selector.select();
  ASSERT_EQ(sel.next_view_sets.size(), want.next_views.size());
  size_t finite = 0;
  for (size_t i = 0; i < want.next_views.size(); ++i) {
    const auto& got = sel.next_view_sets[i];
    EXPECT_EQ(std::vector<int>(got.next_views.begin(), got.next_views.end()), want.next_views[i])
        << "view " << i;
    for (size_t q = 0; q < got.next_views.size(); ++q) {
      EXPECT_EQ(got.error_resistance[q],
                selector.matrix().at(static_cast<core::ViewId>(i), got.next_views[q]));
      ++finite;
    }
  }
  EXPECT_GT(finite, 0u) << "the good frames should see each other";
  EXPECT_EQ(sel.start_view, want.start_view);
  EXPECT_EQ(sel.finite_entries, selector.matrix().table().finiteCount());
  ASSERT_EQ(sel.pairs.size(), want.pairs.size());
  for (size_t p = 0; p < want.pairs.size(); ++p) {
    EXPECT_EQ(sel.pairs[p].first, want.pairs[p].first);
    EXPECT_EQ(sel.pairs[p].second, want.pairs[p].second);
  }

  // An unknown view is still a clean error after all that.
  view_selection::GetNextViews next_views;
  next_views.request.view = static_cast<int>(expected.size());
  ASSERT_TRUE(ros::service::call(node_ + "/get_next_views", next_views));
  EXPECT_FALSE(next_views.response.success);
  next_views.request.view = 0;
  ASSERT_TRUE(ros::service::call(node_ + "/get_next_views", next_views));
  EXPECT_TRUE(next_views.response.success) << next_views.response.message;

  // The latched ~selection catches up with the same keyframes (rate-limited, so wait for it).
  {
    view_selection::ViewSelection::ConstPtr latched;
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
    while (ros::WallTime::now() < deadline) {
      latched = ros::topic::waitForMessage<view_selection::ViewSelection>(node_ + "/selection", nh_,
                                                                          ros::Duration(2.0));
      if (latched && latched->keyframes.size() == expected.size()) break;
      ros::WallDuration(0.05).sleep();
    }
    ASSERT_TRUE(latched) << "nothing on " << node_ << "/selection";
    EXPECT_EQ(latched->keyframes.size(), expected.size());
    EXPECT_EQ(latched->pairs.size(), want.pairs.size());
    EXPECT_EQ(latched->header.frame_id, "world");
  }

  // Markers: one frustum (16 line points) per keyframe, the start view's in its own namespace.
  const auto markers = ros::topic::waitForMessage<visualization_msgs::MarkerArray>(
      node_ + "/markers", nh_, ros::Duration(10.0));
  ASSERT_TRUE(markers) << "no markers";
  size_t frustum_points = 0;
  for (const auto& m : markers->markers)
    if (m.ns == "frusta" || m.ns == "start_view") frustum_points += m.points.size();
  EXPECT_EQ(frustum_points, 16 * expected.size());

  // Export with ~save_keyframe_images: every name in pairs.txt is a written image.
  view_selection::Export exp;
  const fs::path dir =
      fs::temp_directory_path() / ("view_selection_bad_input_" + std::to_string(::getpid()));
  exp.request.directory = dir.string();
  ASSERT_TRUE(ros::service::call(node_ + "/export", exp));
  ASSERT_TRUE(exp.response.success) << exp.response.message;
  EXPECT_EQ(exp.response.images_written, static_cast<int>(expected.size()));
  std::ifstream pairs(exp.response.pairs_txt);
  std::string a, b;
  size_t lines = 0;
  while (pairs >> a >> b) {
    ++lines;
    EXPECT_TRUE(fs::exists(dir / a)) << a;
    EXPECT_TRUE(fs::exists(dir / b)) << b;
  }
  EXPECT_EQ(lines, want.pairs.size());
  EXPECT_TRUE(fs::exists(dir / "selection.png"));
  std::error_code ec;
  fs::remove_all(dir, ec);

  // After ~reset the node starts over: an earlier stamp is fine again.
  std_srvs::Trigger reset;
  ASSERT_TRUE(ros::service::call(node_ + "/reset", reset));
  EXPECT_TRUE(reset.response.success) << reset.response.message;
  ASSERT_TRUE(ros::service::call(node_ + "/get_selection", srv));
  EXPECT_TRUE(srv.response.selection.keyframes.empty());
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  while (handled() != 0 && ros::WallTime::now() < deadline) ros::WallDuration(0.01).sleep();
  ASSERT_EQ(handled(), 0u) << "statistics were not reset";
  ASSERT_TRUE(publish(makeSend(good[0], ros::Time(t0), "cam_" + std::to_string(camera++)), 1));
  ASSERT_TRUE(ros::service::call(node_ + "/get_selection", srv));
  EXPECT_EQ(srv.response.selection.keyframes.size(), 1u);
}

// ~point_source map: keyframes have no points until a cloud comes; a cloud in another frame is
// ignored; a cloud in the world frame gives exactly the rows the core computes from it.
TEST_F(BadInputTest, MapPointsReplaceAndUpdateRows) {
  if (point_source_ != "map") GTEST_SKIP() << "only in map_input.test";
  const std::vector<GoodFrame> good = syntheticFrames(4);
  ASSERT_TRUE(waitForSubscribers()) << "the node under test did not subscribe within 20 s";
  std::vector<ros::Time> stamps;
  for (size_t i = 0; i < good.size(); ++i) {
    stamps.push_back(ros::Time(2000.0 + 0.1 * static_cast<double>(i)));
    ASSERT_TRUE(publish(makeSend(good[i], stamps.back(), "cam"), i + 1));
  }
  view_selection::GetSelection srv;
  ASSERT_TRUE(ros::service::call(node_ + "/get_selection", srv));
  ASSERT_EQ(srv.response.selection.keyframes.size(), good.size());
  EXPECT_EQ(srv.response.selection.finite_entries, 0u);
  for (const auto& kf : srv.response.selection.keyframes) EXPECT_EQ(kf.num_points, 0);

  // The map: points on the surface frame 0 sees, back-projected from its depth.
  Eigen::Matrix3Xd map = sampleDepthPoints(depthImageOf(good[0].depth), good[0].intrinsics,
                                           good[0].pose, DepthSamplerConfig{});
  ASSERT_GT(map.cols(), 50);
  auto cloud = [&](const std::string& frame) {
    sensor_msgs::PointCloud2 c;
    c.header.frame_id = frame;
    c.header.stamp = ros::Time(2001.0);
    sensor_msgs::PointCloud2Modifier modifier(c);
    modifier.setPointCloud2FieldsByString(1, "xyz");
    modifier.resize(static_cast<size_t>(map.cols()) + 1);
    sensor_msgs::PointCloud2Iterator<float> x(c, "x"), y(c, "y"), z(c, "z");
    for (Eigen::Index i = 0; i < map.cols(); ++i, ++x, ++y, ++z) {
      *x = static_cast<float>(map(0, i));
      *y = static_cast<float>(map(1, i));
      *z = static_cast<float>(map(2, i));
    }
    *x = *y = *z = std::numeric_limits<float>::quiet_NaN();  // skipped, as organised clouds pad
    return c;
  };
  points_pub_.publish(cloud("mars"));
  ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  auto badMaps = [&] {
    const auto s = stats();
    for (size_t i = 0; s && i < s->drop_reasons.size(); ++i)
      if (s->drop_reasons[i] == "bad_map") return s->drop_counts[i];
    return uint64_t{0};
  };
  while (badMaps() < 1 && ros::WallTime::now() < deadline) ros::WallDuration(0.01).sleep();
  EXPECT_EQ(badMaps(), 1u) << "a cloud outside ~world_frame must be ignored and counted";

  points_pub_.publish(cloud("/world"));
  deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  while (ros::WallTime::now() < deadline) {
    ASSERT_TRUE(ros::service::call(node_ + "/get_selection", srv));
    if (srv.response.selection.finite_entries > 0) break;
    ros::WallDuration(0.02).sleep();
  }
  const auto& sel = srv.response.selection;
  ASSERT_GT(sel.finite_entries, 0u) << "the map never reached the keyframes";

  // The core with the same frames and the same (float-rounded) map.
  core::ViewSelectorConfig config;
  config.keyframes.mode = core::KeyframeMode::kEveryFrame;
  config.selection.k = k_;
  core::ViewSelector selector(config, std::make_unique<MapPointSource>());
  for (size_t i = 0; i < good.size(); ++i) {
    core::Frame f;
    f.stamp = stamps[i].toSec();
    f.image_name = ros_node::keyframeImageName(f.stamp);
    f.intrinsics = good[i].intrinsics;
    f.pose = good[i].pose;
    f.pose.orientation.normalize();
    f.depth = depthImageOf(good[i].depth);
    ASSERT_EQ(selector.addFrame(f).outcome, core::FrameOutcome::kKeyframe);
  }
  dynamic_cast<MapPointSource&>(selector.pointSource())
      .setMapPoints(map.cast<float>().cast<double>());
  selector.applyPointUpdates();
  EXPECT_EQ(sel.finite_entries, selector.matrix().table().finiteCount());
  for (size_t i = 0; i < good.size(); ++i) {
    EXPECT_EQ(sel.keyframes[i].num_points,
              selector.matrix().keyframe(static_cast<core::ViewId>(i)).points.cols())
        << i;
    for (size_t q = 0; q < sel.next_view_sets[i].next_views.size(); ++q)
      EXPECT_EQ(
          sel.next_view_sets[i].error_resistance[q],
          selector.matrix().at(static_cast<core::ViewId>(i), sel.next_view_sets[i].next_views[q]));
  }
}

// bad_input_odom_frame.test: ~use_path_corrections with ~odom_frame "odom" (as rtabmap.launch).
// A frame whose world <- camera is on tf but not odom <- camera (odom is not on its chain) is a
// no_pose drop whose message names ~odom_frame, and the node goes on: the next frame, looked up
// through world -> odom -> camera, is a keyframe at the composed pose.
TEST_F(BadInputTest, OdomFrameOffTheChainIsANoPoseNamingIt) {
  std::string odom;
  if (!ros::NodeHandle("~").getParam("odom_frame", odom))
    GTEST_SKIP() << "bad_input_odom_frame.test runs it";
  const std::vector<GoodFrame> good = syntheticFrames(2);
  ASSERT_TRUE(waitForSubscribers()) << "the node under test did not subscribe within 20 s";
  Send off = makeSend(good[0], ros::Time(1000.1), "cam_off");  // world -> cam_off only
  ASSERT_TRUE(publish(off, 1));
  auto s = stats();
  ASSERT_TRUE(s);
  EXPECT_EQ(s->frames_offered, 0u);
  EXPECT_EQ(s->frames_dropped, 1u);
  ASSERT_EQ(s->drop_reasons.size(), s->drop_counts.size());
  const auto reason = std::find(s->drop_reasons.begin(), s->drop_reasons.end(), "no_pose");
  ASSERT_NE(reason, s->drop_reasons.end());
  EXPECT_EQ(s->drop_counts[static_cast<size_t>(reason - s->drop_reasons.begin())], 1u);
  EXPECT_NE(s->last_error.find("~odom_frame"), std::string::npos) << s->last_error;
  EXPECT_NE(s->last_error.find(odom + " <- cam_off"), std::string::npos) << s->last_error;

  // world -> odom -> cam_on: a keyframe at world <- odom * odom <- cam_on.
  core::CameraPose world_odom;
  world_odom.position = {0.3, -0.2, 0.1};
  world_odom.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()));
  const ros::Time stamp(1000.2);
  geometry_msgs::TransformStamped link;
  link.header.stamp = stamp;
  link.header.frame_id = "world";
  link.child_frame_id = odom;
  link.transform = ros_node::transformToMsg(world_odom);
  tf2_msgs::TFMessage m;
  m.transforms.push_back(link);
  tf_pub_.publish(m);
  Send on = makeSend(good[1], stamp, "cam_on");
  on.camera_frame.clear();  // published below, as a child of odom
  const core::CameraPose odom_camera =
      core::composePoses(core::inversePose(world_odom), good[1].pose);
  geometry_msgs::TransformStamped camera_link;
  camera_link.header.stamp = stamp;
  camera_link.header.frame_id = odom;
  camera_link.child_frame_id = "cam_on";
  camera_link.transform = ros_node::transformToMsg(odom_camera);
  tf2_msgs::TFMessage c;
  c.transforms.push_back(camera_link);
  tf_pub_.publish(c);
  ASSERT_TRUE(publish(on, 2));
  s = stats();
  EXPECT_EQ(s->frames_offered, 1u) << s->last_error;
  view_selection::GetSelection srv;
  ASSERT_TRUE(ros::service::call(node_ + "/get_selection", srv));
  ASSERT_EQ(srv.response.selection.keyframes.size(), 1u);
  const auto& p = srv.response.selection.keyframes[0].pose.position;
  EXPECT_NEAR(p.x, good[1].pose.position.x(), 1e-6);
  EXPECT_NEAR(p.y, good[1].pose.position.y(), 1e-6);
  EXPECT_NEAR(p.z, good[1].pose.position.z(), 1e-6);
}

// bounded_outputs.test: ~publish_max_views 3. Every message on ~selection stays within 3 views
// once the map is larger, the updates applied in order rebuild exactly what ~get_selection
// returns (all views), and ~markers draws a bounded summary.
TEST_F(BadInputTest, BoundedSelectionAndMarkers) {
  int max_views = 0;
  if (!ros::NodeHandle("~").getParam("publish_max_views", max_views))
    GTEST_SKIP() << "only in bounded_outputs.test";
  ASSERT_GT(max_views, 0);
  std::mutex m;
  std::vector<view_selection::ViewSelection::ConstPtr> updates;
  visualization_msgs::MarkerArray::ConstPtr markers;
  ros::Subscriber sel_sub = nh_.subscribe<view_selection::ViewSelection>(
      node_ + "/selection", 1000, [&](const view_selection::ViewSelection::ConstPtr& msg) {
        std::lock_guard<std::mutex> lock(m);
        updates.push_back(msg);
      });
  ros::Subscriber marker_sub = nh_.subscribe<visualization_msgs::MarkerArray>(
      node_ + "/markers", 10, [&](const visualization_msgs::MarkerArray::ConstPtr& msg) {
        std::lock_guard<std::mutex> lock(m);
        markers = msg;
      });
  const size_t count = 12;
  std::vector<GoodFrame> good = syntheticFrames(count);
  for (size_t i = 0; i < count; ++i)  // images that differ, for the read-back below
    for (int v = 0; v < good[i].image.rows; ++v)
      for (int u = 0; u < good[i].image.cols; ++u)
        good[i].image.at<cv::Vec3b>(v, u) = cv::Vec3b(static_cast<uint8_t>(u + 7 * i),
                                                      static_cast<uint8_t>(v * 2 + i), 200);
  ASSERT_TRUE(waitForSubscribers()) << "the node under test did not subscribe within 20 s";
  std::string bad_dir_node;
  ros::NodeHandle("~").getParam("bad_dir_node", bad_dir_node);
  if (!bad_dir_node.empty()) {  // both nodes take the same frames
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(20.0);
    while ((image_pub_.getNumSubscribers() < 2 || depth_pub_.getNumSubscribers() < 2 ||
            info_pub_.getNumSubscribers() < 2 || tf_pub_.getNumSubscribers() < 2) &&
           ros::WallTime::now() < until)
      ros::WallDuration(0.05).sleep();
    ASSERT_GE(image_pub_.getNumSubscribers(), 2u) << bad_dir_node << " did not subscribe";
  }
  // The latched (empty, whole) selection first, so the updates start from a full message.
  ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  auto received = [&] {
    std::lock_guard<std::mutex> lock(m);
    return updates.size();
  };
  while (received() == 0 && ros::WallTime::now() < deadline) ros::WallDuration(0.01).sleep();
  ASSERT_GT(received(), 0u) << "no latched message on ~selection";
  for (size_t i = 0; i < count; ++i)
    ASSERT_TRUE(publish(makeSend(good[i], ros::Time(3000.0 + 0.1 * double(i)), "cam"), i + 1));

  view_selection::GetSelection srv;
  ASSERT_TRUE(ros::service::call(node_ + "/get_selection", srv));
  const view_selection::ViewSelection& all = srv.response.selection;
  ASSERT_EQ(all.keyframes.size(), count) << "~get_selection must give every keyframe";
  ASSERT_EQ(all.next_view_sets.size(), count);
  EXPECT_FALSE(all.partial);
  EXPECT_EQ(all.total_keyframes, count);
  EXPECT_FALSE(all.pairs.empty());
  EXPECT_FALSE(all.order.empty());

  // Wait (bounded) for the update that has caught up with all keyframes and left nothing out.
  deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  auto caughtUp = [&] {
    std::lock_guard<std::mutex> lock(m);
    return !updates.empty() && updates.back()->total_keyframes == count &&
           updates.back()->pending_views == 0 && markers &&
           std::any_of(markers->markers.begin(), markers->markers.end(),
                       [](const auto& mk) { return mk.ns == "next_views"; });
  };
  while (!caughtUp() && ros::WallTime::now() < deadline) ros::WallDuration(0.01).sleep();
  ASSERT_TRUE(caughtUp()) << "~selection did not catch up with " << count << " keyframes";
  ros::WallDuration(0.3).sleep();  // nothing changes any more: no later update may differ

  std::lock_guard<std::mutex> lock(m);
  std::map<int32_t, view_selection::KeyframeInfo> keyframes;
  std::map<int32_t, view_selection::NextViewSet> sets;
  bool saw_partial = false;
  for (size_t u = 0; u < updates.size(); ++u) {
    const auto& msg = *updates[u];
    if (u > 0) {
      EXPECT_EQ(msg.update, updates[u - 1]->update + 1) << "an update was missed";
    }
    EXPECT_EQ(msg.keyframes.size(), msg.next_view_sets.size());
    if (msg.total_keyframes > static_cast<uint32_t>(max_views)) {
      EXPECT_TRUE(msg.partial) << "update " << msg.update << " of " << msg.total_keyframes
                               << " keyframes is not bounded";
      EXPECT_LE(msg.keyframes.size(), static_cast<size_t>(max_views)) << "update " << msg.update;
      EXPECT_LE(msg.next_view_sets.size(), static_cast<size_t>(max_views));
      EXPECT_TRUE(msg.pairs.empty() && msg.order.empty() && msg.completed.empty());
    } else {
      EXPECT_FALSE(msg.partial);
      EXPECT_EQ(msg.keyframes.size(), msg.total_keyframes);
    }
    saw_partial = saw_partial || msg.partial;
    if (!msg.partial) {
      keyframes.clear();
      sets.clear();
    }
    for (const auto& kf : msg.keyframes) keyframes[kf.id] = kf;
    for (const auto& set : msg.next_view_sets) sets[set.view] = set;
  }
  EXPECT_TRUE(saw_partial);
  const auto& last = *updates.back();
  EXPECT_EQ(last.start_view, all.start_view);
  EXPECT_EQ(last.finite_entries, all.finite_entries);
  ASSERT_EQ(keyframes.size(), count) << "the updates left views out";
  ASSERT_EQ(sets.size(), count);
  for (size_t i = 0; i < count; ++i) {
    const auto id = static_cast<int32_t>(i);
    EXPECT_EQ(keyframes[id], all.keyframes[i]) << "keyframe " << i;
    EXPECT_EQ(sets[id], all.next_view_sets[i]) << "next view set " << i << " is stale";
  }

  // Markers: frusta of every m-th view, the start view and the newest, m = ceil(n / max_views).
  size_t frustum_points = 0;
  for (const auto& mk : markers->markers)
    if (mk.ns == "frusta" || mk.ns == "start_view") frustum_points += mk.points.size();
  const size_t stride = (count + static_cast<size_t>(max_views) - 1) / static_cast<size_t>(max_views);
  const size_t per_frustum = 16;
  EXPECT_GE(frustum_points, per_frustum * ((count + stride - 1) / stride));
  EXPECT_LE(frustum_points, per_frustum * ((count + stride - 1) / stride + 2));
  EXPECT_LT(frustum_points, per_frustum * count) << "~markers draws every keyframe";

  // ~image_cache_mb 0.1 holds one of these images (160 x 120 x 3 bytes): ~export reads the
  // others back from ~image_dir, every one equal to what was sent.
  view_selection::Export exp;
  exp.request.directory =
      (fs::temp_directory_path() / ("view_selection_bounded_" + std::to_string(::getpid())))
          .string();
  ASSERT_TRUE(ros::service::call(node_ + "/export", exp));
  ASSERT_TRUE(exp.response.success) << exp.response.message;
  EXPECT_EQ(exp.response.images_written, static_cast<int>(count)) << exp.response.message;
  for (size_t i = 0; i < count; ++i) {
    const cv::Mat back = cv::imread(
        (fs::path(exp.request.directory) / all.keyframes[i].image_name).string(),
        cv::IMREAD_COLOR);
    ASSERT_FALSE(back.empty()) << all.keyframes[i].image_name << " was not exported";
    EXPECT_EQ(cv::norm(back, good[i].image, cv::NORM_INF), 0.0)
        << "exported image " << i << " differs from the one sent";
  }
  fs::remove_all(exp.request.directory);

  if (bad_dir_node.empty()) return;
  // ~image_dir below a regular file: the images beyond the one that fits in RAM are lost, the
  // node answers, and ~export says so and why.
  view_selection::GetSelection bad_sel;
  ASSERT_TRUE(ros::service::waitForService(bad_dir_node + "/get_selection", ros::Duration(10.0)));
  deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  while (ros::WallTime::now() < deadline) {
    ASSERT_TRUE(ros::service::call(bad_dir_node + "/get_selection", bad_sel));
    if (bad_sel.response.selection.keyframes.size() == count) break;
    ros::WallDuration(0.02).sleep();
  }
  ASSERT_EQ(bad_sel.response.selection.keyframes.size(), count);
  view_selection::Export bad_exp;
  bad_exp.request.directory = exp.request.directory + "_bad_dir";
  ASSERT_TRUE(ros::service::call(bad_dir_node + "/export", bad_exp));
  EXPECT_TRUE(bad_exp.response.success) << bad_exp.response.message;
  EXPECT_EQ(bad_exp.response.images_written, 1) << bad_exp.response.message;
  EXPECT_NE(bad_exp.response.message.find("lost"), std::string::npos) << bad_exp.response.message;
  EXPECT_NE(bad_exp.response.message.find("/proc/version"), std::string::npos)
      << bad_exp.response.message;
  fs::remove_all(bad_exp.request.directory);
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_bad_input");
  ros::NodeHandle nh;
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
