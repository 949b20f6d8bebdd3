#include "point_source_codecs.h"

#include <cstring>

namespace view_selection::session {

using io::readDepthMap;
using io::readIntrinsics;
using io::readPoints;
using io::readPose;
using io::writeDepthMap;
using io::writeIntrinsics;
using io::writePoints;
using io::writePose;

void writeMapState(io::BinaryWriter& w, const points::MapPointSource::State& s) {
  writePoints(w, s.map);
  w.u64(s.views.size());
  for (const auto& v : s.views) {
    w.i32(v.id);
    writeIntrinsics(w, v.intrinsics);
    writePose(w, v.pose);
    writeDepthMap(w, v.depth);
    writePoints(w, v.assigned);
    w.flag(v.pending);
  }
}
points::MapPointSource::State readMapState(io::BinaryReader& r) {
  points::MapPointSource::State s;
  s.map = readPoints(r);
  s.views.resize(r.count(100, "map keyframes"));
  for (auto& v : s.views) {
    v.id = r.i32("map keyframe");
    v.intrinsics = readIntrinsics(r);
    v.pose = readPose(r);
    v.depth = readDepthMap(r);
    v.assigned = readPoints(r);
    v.pending = r.flag("map keyframe");
  }
  return s;
}

void writeFeatureState(io::BinaryWriter& w, const points::FeaturePointSource::State& s) {
  w.u64(s.views.size());
  for (const auto& v : s.views) {
    w.i32(v.id);
    writeIntrinsics(w, v.intrinsics);
    writePose(w, v.pose);
    w.u64(v.keypoints.size());
    for (const cv::KeyPoint& k : v.keypoints) {
      w.f32(k.pt.x);
      w.f32(k.pt.y);
      w.f32(k.size);
      w.f32(k.angle);
      w.f32(k.response);
      w.i32(k.octave);
      w.i32(k.class_id);
    }
    const cv::Mat d = v.descriptors.isContinuous() ? v.descriptors : v.descriptors.clone();
    w.i32(d.rows);
    w.i32(d.cols);
    w.i32(d.type());
    w.raw(d.data, d.empty() ? 0 : d.total() * d.elemSize());
    for (const int t : v.track_of) w.i32(t);
    w.f64(v.median_depth);
    writePoints(w, v.emitted);
  }
  w.u64(s.tracks.size());
  for (const auto& t : s.tracks) {
    w.u64(t.obs.size());
    for (const auto& [view, feature] : t.obs) {
      w.i32(view);
      w.i32(feature);
    }
    for (int c = 0; c < 3; ++c) w.f64(t.point[c]);
    w.flag(t.valid);
    w.flag(t.alive);
  }
}
points::FeaturePointSource::State readFeatureState(io::BinaryReader& r) {
  points::FeaturePointSource::State s;
  s.views.resize(r.count(100, "feature keyframes"));
  for (auto& v : s.views) {
    v.id = r.i32("feature keyframe");
    v.intrinsics = readIntrinsics(r);
    v.pose = readPose(r);
    v.keypoints.resize(r.count(28, "keypoints"));
    for (cv::KeyPoint& k : v.keypoints) {
      k.pt.x = r.f32("keypoint");
      k.pt.y = r.f32("keypoint");
      k.size = r.f32("keypoint");
      k.angle = r.f32("keypoint");
      k.response = r.f32("keypoint");
      k.octave = r.i32("keypoint");
      k.class_id = r.i32("keypoint");
    }
    const int rows = r.i32("descriptors"), cols = r.i32("descriptors"), type = r.i32("descriptors");
    if (rows < 0 || cols < 0 || (type != CV_8U && type != CV_32F))
      r.fail("bad descriptor matrix shape or type");
    const size_t element = type == CV_8U ? 1 : 4;
    if (cols > 0 && static_cast<size_t>(rows) > r.left() / (static_cast<size_t>(cols) * element))
      r.fail("truncated in descriptors");
    const size_t bytes = static_cast<size_t>(rows) * static_cast<size_t>(cols) * element;
    const uint8_t* p = r.take(bytes, "descriptors");
    if (rows > 0 && cols > 0) {
      v.descriptors.create(rows, cols, type);
      std::memcpy(v.descriptors.data, p, bytes);
    }
    v.track_of.resize(v.keypoints.size());
    for (int& t : v.track_of) t = r.i32("track of feature");
    v.median_depth = r.finite("median depth");
    v.emitted = readPoints(r);
  }
  s.tracks.resize(r.count(34, "tracks"));
  for (auto& t : s.tracks) {
    t.obs.resize(r.count(8, "track observations"));
    for (auto& [view, feature] : t.obs) {
      view = r.i32("track observation");
      feature = r.i32("track observation");
    }
    for (int c = 0; c < 3; ++c) t.point[c] = r.finite("track point");
    t.valid = r.flag("track");
    t.alive = r.flag("track");
  }
  return s;
}

}  // namespace view_selection::session
