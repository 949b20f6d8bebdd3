// The node's RViz markers (ros/markers.h) for a selection of three keyframes, the last of which
// names the first as the keyframe it revisits: a frustum each, and the "revisits" line between
// the two (no master).
#include "view_selection/ros/markers.h"

#include <gtest/gtest.h>

#include <string>

namespace view_selection::ros_node {
namespace {

core::KeyframeSummary keyframeAt(double x, int revisit_of = -1) {
  core::KeyframeSummary k;
  k.intrinsics = {100.0, 100.0, 50.0, 40.0, 100, 80};
  k.pose.position = Eigen::Vector3d(x, 0.0, 1.0);
  k.revisit_of = revisit_of;
  return k;
}

const visualization_msgs::Marker* find(const visualization_msgs::MarkerArray& a,
                                       const std::string& ns) {
  for (const visualization_msgs::Marker& m : a.markers)
    if (m.ns == ns) return &m;
  return nullptr;
}

TEST(Markers, AKeyframeThatRevisitsAnotherIsJoinedToIt) {
  core::SelectionOutput out;
  out.keyframes.push_back(keyframeAt(0.0));
  out.keyframes.push_back(keyframeAt(1.0));
  out.keyframes.push_back(keyframeAt(2.5, 0));
  const visualization_msgs::MarkerArray a = selectionMarkers(out, "map", 0.2);
  ASSERT_FALSE(a.markers.empty());
  EXPECT_EQ(a.markers.front().action, visualization_msgs::Marker::DELETEALL);
  const visualization_msgs::Marker* frusta = find(a, "frusta");
  ASSERT_NE(frusta, nullptr);
  EXPECT_EQ(frusta->points.size(), 3u * 16u);  // 8 lines a keyframe
  const visualization_msgs::Marker* revisits = find(a, "revisits");
  ASSERT_NE(revisits, nullptr);
  ASSERT_EQ(revisits->points.size(), 2u);
  EXPECT_DOUBLE_EQ(revisits->points[0].x, 2.5);
  EXPECT_DOUBLE_EQ(revisits->points[1].x, 0.0);
  EXPECT_EQ(revisits->header.frame_id, "map");

  // Without a link there is no such marker (an empty one would be an RViz warning).
  out.keyframes.edit(2).revisit_of = -1;
  EXPECT_EQ(find(selectionMarkers(out, "map", 0.2), "revisits"), nullptr);
}

}  // namespace
}  // namespace view_selection::ros_node
