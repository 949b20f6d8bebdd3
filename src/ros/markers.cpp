#include "view_selection/ros/markers.h"

#include <geometry_msgs/Point.h>

namespace view_selection::ros_node {

namespace {

geometry_msgs::Point point(const Eigen::Vector3d& p) {
  geometry_msgs::Point m;
  m.x = p.x();
  m.y = p.y();
  m.z = p.z();
  return m;
}

visualization_msgs::Marker lineList(const std::string& ns, const std::string& frame, double width,
                                    float r, float g, float b, float a) {
  visualization_msgs::Marker m;
  m.header.frame_id = frame;
  m.ns = ns;
  m.id = 0;
  m.type = visualization_msgs::Marker::LINE_LIST;
  m.action = visualization_msgs::Marker::ADD;
  m.pose.orientation.w = 1.0;
  m.scale.x = width;
  m.color.r = r;
  m.color.g = g;
  m.color.b = b;
  m.color.a = a;
  return m;
}

void addFrustum(visualization_msgs::Marker& m, const core::KeyframeSummary& kf, double scale) {
  const core::PinholeIntrinsics& k = kf.intrinsics;
  const Eigen::Matrix3d R = kf.pose.rotation();
  const Eigen::Vector3d o = kf.pose.position;
  const Eigen::Vector2d px[4] = {{0.0, 0.0},
                                 {double(k.width), 0.0},
                                 {double(k.width), double(k.height)},
                                 {0.0, double(k.height)}};
  Eigen::Vector3d corner[4];
  for (int c = 0; c < 4; ++c) corner[c] = o + R * (k.backProject(px[c]) * scale);
  for (int c = 0; c < 4; ++c) {
    m.points.push_back(point(o));
    m.points.push_back(point(corner[c]));
    m.points.push_back(point(corner[c]));
    m.points.push_back(point(corner[(c + 1) % 4]));
  }
}

}  // namespace

visualization_msgs::MarkerArray selectionMarkers(const core::SelectionOutput& snapshot,
                                                 const std::string& world_frame, double scale,
                                                 size_t max_views) {
  const core::ChunkedSelection& selection = snapshot.selection;
  visualization_msgs::MarkerArray array;
  visualization_msgs::Marker clear;
  clear.header.frame_id = world_frame;
  clear.action = visualization_msgs::Marker::DELETEALL;
  array.markers.push_back(clear);

  const double width = 0.05 * scale;
  auto frusta = lineList("frusta", world_frame, width, 0.6f, 0.6f, 0.6f, 1.0f);
  auto start = lineList("start_view", world_frame, 2.0 * width, 1.0f, 0.1f, 0.1f, 1.0f);
  auto edges = lineList("next_views", world_frame, width, 0.1f, 0.5f, 1.0f, 0.8f);
  auto completion = lineList("completion", world_frame, 1.5 * width, 1.0f, 0.6f, 0.0f, 0.9f);
  auto revisits = lineList("revisits", world_frame, 2.0 * width, 0.9f, 0.1f, 0.9f, 0.9f);
  const size_t n = snapshot.size();
  const size_t stride = max_views == 0 || n <= max_views ? 1 : (n + max_views - 1) / max_views;
  auto drawn = [&](size_t i) {
    return i % stride == 0 || static_cast<core::ViewId>(i) == selection.start_view || i + 1 == n;
  };
  for (size_t i = 0; i < n; ++i) {
    if (!drawn(i)) continue;
    const core::KeyframeSummary& kf = snapshot.keyframes[i];
    addFrustum(static_cast<core::ViewId>(i) == selection.start_view ? start : frusta, kf, scale);
    // A keyframe that names the keyframe it revisits (recognised from the images): the line's
    // length is the drift the poses have between the two passes, plus the baseline.
    if (kf.revisit_of >= 0 && static_cast<size_t>(kf.revisit_of) < n) {
      revisits.points.push_back(point(kf.pose.position));
      revisits.points.push_back(
          point(snapshot.keyframes[static_cast<size_t>(kf.revisit_of)].pose.position));
    }
  }
  for (size_t i = 0; i < selection.final_next_views.size() && i < n; ++i) {
    if (!drawn(i)) continue;
    const Eigen::Vector3d from = snapshot.keyframes[i].pose.position;
    const auto& fin = selection.final_next_views[i];
    const size_t selected = i < selection.next_views.size() ? selection.next_views[i].size() : 0;
    for (size_t q = 0; q < fin.size(); ++q) {
      auto& target = q < selected ? edges : completion;
      target.points.push_back(point(from));
      target.points.push_back(point(snapshot.keyframes[static_cast<size_t>(fin[q])].pose.position));
    }
  }
  for (auto* m : {&frusta, &start, &edges, &completion, &revisits})
    if (!m->points.empty()) array.markers.push_back(*m);
  return array;
}

}  // namespace view_selection::ros_node
