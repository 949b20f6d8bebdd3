#include "view_selection/io/state_file.h"

#include "view_selection/io/atomic_file.h"
#include "view_selection/points/point_source_factory.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <stdio.h>
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <functional>
#include <limits>
#include <variant>

namespace view_selection::io {

namespace {

namespace fs = std::filesystem;

// docs/state_file.md: the header.
constexpr std::array<uint8_t, 8> kMagic = {0x89, 'V', 'S', 'S', '\r', '\n', 0x1a, '\n'};
constexpr size_t kHeaderSize = 32;
constexpr int kMaxImageSide = 1 << 20;  // [px] a saved width or height beyond this is corrupt
constexpr int kMaxParamDepth = 8;

// Section tags, in the order they are written.
constexpr uint32_t tag(const char (&t)[5]) {
  return static_cast<uint32_t>(static_cast<uint8_t>(t[0])) |
         static_cast<uint32_t>(static_cast<uint8_t>(t[1])) << 8 |
         static_cast<uint32_t>(static_cast<uint8_t>(t[2])) << 16 |
         static_cast<uint32_t>(static_cast<uint8_t>(t[3])) << 24;
}
constexpr uint32_t kSession = tag("SESS"), kConfig = tag("CONF"), kKeyframes = tag("KEYF"),
                   kMatrix = tag("MATX"), kPolicy = tag("PLCY"), kPoints = tag("PSRC"),
                   kStatistics = tag("STAT"), kPairStream = tag("PAIR"),
                   kJournalBase = tag("JRNL");

enum class ParamKind : uint8_t { kBool = 0, kInt = 1, kDouble = 2, kString = 3, kGroup = 4 };
enum class SourceKind : uint8_t { kNone = 0, kMap = 1, kFeatures = 2 };

// ---------------------------------------------------------------------------------------------
// Little-endian writing.

class Writer {
 public:
  std::vector<uint8_t> bytes;

  void u8(uint8_t v) { bytes.push_back(v); }
  void u32(uint32_t v) {
    for (int b = 0; b < 4; ++b) bytes.push_back(static_cast<uint8_t>(v >> (8 * b)));
  }
  void u64(uint64_t v) {
    for (int b = 0; b < 8; ++b) bytes.push_back(static_cast<uint8_t>(v >> (8 * b)));
  }
  void i32(int32_t v) { u32(static_cast<uint32_t>(v)); }
  void i64(int64_t v) { u64(static_cast<uint64_t>(v)); }
  void f32(float v) {
    uint32_t b;
    std::memcpy(&b, &v, 4);
    u32(b);
  }
  void f64(double v) {
    uint64_t b;
    std::memcpy(&b, &v, 8);
    u64(b);
  }
  void flag(bool v) { u8(v ? 1 : 0); }
  void text(const std::string& s) {
    u32(static_cast<uint32_t>(s.size()));
    bytes.insert(bytes.end(), s.begin(), s.end());
  }
  void raw(const uint8_t* data, size_t size) { bytes.insert(bytes.end(), data, data + size); }

  /// Starts a section; end it with endSection(start).
  size_t beginSection(uint32_t t) {
    u32(t);
    const size_t at = bytes.size();
    u64(0);
    return at;
  }
  void endSection(size_t at) {
    const uint64_t length = bytes.size() - at - 8;
    for (int b = 0; b < 8; ++b)
      bytes[at + static_cast<size_t>(b)] = static_cast<uint8_t>(length >> (8 * b));
  }
};

// ---------------------------------------------------------------------------------------------
// Reading: every read is bounded by what is left, so no input makes it read past the end or
// allocate more than the file could hold.

class Reader {
 public:
  Reader(const uint8_t* data, size_t size, std::string context)
      : data_(data), size_(size), context_(std::move(context)) {}

  [[noreturn]] void fail(const std::string& what) const {
    throw StateFileError(context_ + ": " + what + " (at byte " + std::to_string(pos_) + ")");
  }
  size_t left() const { return size_ - pos_; }
  bool done() const { return pos_ == size_; }
  const uint8_t* take(size_t n, const char* what) {
    if (n > left()) fail(std::string("truncated in ") + what);
    const uint8_t* p = data_ + pos_;
    pos_ += n;
    return p;
  }
  uint8_t u8(const char* what) { return *take(1, what); }
  uint32_t u32(const char* what) {
    const uint8_t* p = take(4, what);
    uint32_t v = 0;
    for (int b = 0; b < 4; ++b) v |= static_cast<uint32_t>(p[b]) << (8 * b);
    return v;
  }
  uint64_t u64(const char* what) {
    const uint8_t* p = take(8, what);
    uint64_t v = 0;
    for (int b = 0; b < 8; ++b) v |= static_cast<uint64_t>(p[b]) << (8 * b);
    return v;
  }
  int32_t i32(const char* what) { return static_cast<int32_t>(u32(what)); }
  int64_t i64(const char* what) { return static_cast<int64_t>(u64(what)); }
  float f32(const char* what) {
    const uint32_t b = u32(what);
    float v;
    std::memcpy(&v, &b, 4);
    return v;
  }
  double f64(const char* what) {
    const uint64_t b = u64(what);
    double v;
    std::memcpy(&v, &b, 8);
    return v;
  }
  double finite(const char* what) {
    const double v = f64(what);
    if (!std::isfinite(v)) fail(std::string("non-finite ") + what);
    return v;
  }
  bool flag(const char* what) {
    const uint8_t v = u8(what);
    if (v > 1) fail(std::string("bad flag in ") + what);
    return v == 1;
  }
  std::string text(const char* what) {
    const uint32_t n = u32(what);
    const uint8_t* p = take(n, what);
    return std::string(reinterpret_cast<const char*>(p), n);
  }
  /// A count of elements of at least `element_bytes` each, checked against what is left.
  size_t count(size_t element_bytes, const char* what) {
    const uint64_t n = u64(what);
    if (element_bytes > 0 && n > left() / element_bytes) fail(std::string("bad count in ") + what);
    return static_cast<size_t>(n);
  }
  Reader section(size_t length, const std::string& name) {
    const uint8_t* p = take(length, name.c_str());
    return Reader(p, length, context_ + ", section " + name);
  }
  void expectEnd(const char* what) const {
    if (!done()) fail(std::to_string(left()) + " unexpected bytes at the end of " + what);
  }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  std::string context_;
};

// ---------------------------------------------------------------------------------------------
// Pieces.

void writeIntrinsics(Writer& w, const core::PinholeIntrinsics& k) {
  w.f64(k.fx);
  w.f64(k.fy);
  w.f64(k.cx);
  w.f64(k.cy);
  w.i32(k.width);
  w.i32(k.height);
}
core::PinholeIntrinsics readIntrinsics(Reader& r) {
  core::PinholeIntrinsics k;
  k.fx = r.f64("intrinsics");
  k.fy = r.f64("intrinsics");
  k.cx = r.f64("intrinsics");
  k.cy = r.f64("intrinsics");
  k.width = r.i32("intrinsics");
  k.height = r.i32("intrinsics");
  if (!k.isValid() || k.width > kMaxImageSide || k.height > kMaxImageSide)
    r.fail("invalid intrinsics");
  return k;
}

void writePose(Writer& w, const core::CameraPose& p) {
  for (int c = 0; c < 3; ++c) w.f64(p.position[c]);
  w.f64(p.orientation.x());
  w.f64(p.orientation.y());
  w.f64(p.orientation.z());
  w.f64(p.orientation.w());
}
core::CameraPose readPose(Reader& r) {
  core::CameraPose p;
  for (int c = 0; c < 3; ++c) p.position[c] = r.f64("pose");
  const double x = r.f64("pose"), y = r.f64("pose"), z = r.f64("pose"), w = r.f64("pose");
  p.orientation = Eigen::Quaterniond(w, x, y, z);
  if (!p.isValid()) r.fail("invalid pose");
  return p;
}

void writePoints(Writer& w, const Eigen::Matrix3Xd& points) {
  w.u64(static_cast<uint64_t>(points.cols()));
  for (Eigen::Index c = 0; c < points.cols(); ++c)
    for (int d = 0; d < 3; ++d) w.f64(points(d, c));
}
Eigen::Matrix3Xd readPoints(Reader& r) {
  const size_t n = r.count(24, "points");
  Eigen::Matrix3Xd points(3, static_cast<Eigen::Index>(n));
  for (size_t c = 0; c < n; ++c)
    for (int d = 0; d < 3; ++d) points(d, static_cast<Eigen::Index>(c)) = r.finite("point");
  return points;
}

void writeDepthMap(Writer& w, const std::shared_ptr<const core::DepthMap>& map) {
  w.flag(map != nullptr);
  if (!map) return;
  w.i32(map->cols);
  w.i32(map->rows);
  w.f64(map->cell_width);
  w.f64(map->cell_height);
  w.u64(map->depth.size());
  for (const float d : map->depth) w.f32(d);
}
std::shared_ptr<const core::DepthMap> readDepthMap(Reader& r) {
  if (!r.flag("depth map")) return nullptr;
  auto map = std::make_shared<core::DepthMap>();
  map->cols = r.i32("depth map");
  map->rows = r.i32("depth map");
  map->cell_width = r.f64("depth map");
  map->cell_height = r.f64("depth map");
  map->depth.resize(r.count(4, "depth map"));
  for (float& d : map->depth) d = r.f32("depth map");
  if (!map->isConsistent()) r.fail("inconsistent depth map");
  return map;
}

void writeParams(Writer& w, const core::Params& params) {
  w.u32(static_cast<uint32_t>(params.size()));
  for (const core::Param& p : params) {
    w.text(p.name);
    if (p.group) {
      w.u8(static_cast<uint8_t>(ParamKind::kGroup));
      writeParams(w, p.children);
      continue;
    }
    std::visit(
        [&](const auto& v) {
          using T = std::decay_t<decltype(v)>;
          if constexpr (std::is_same_v<T, bool>) {
            w.u8(static_cast<uint8_t>(ParamKind::kBool));
            w.flag(v);
          } else if constexpr (std::is_same_v<T, int>) {
            w.u8(static_cast<uint8_t>(ParamKind::kInt));
            w.i32(v);
          } else if constexpr (std::is_same_v<T, double>) {
            w.u8(static_cast<uint8_t>(ParamKind::kDouble));
            w.f64(v);
          } else {
            w.u8(static_cast<uint8_t>(ParamKind::kString));
            w.text(v);
          }
        },
        p.value);
  }
}
core::Params readParams(Reader& r, int depth = 0) {
  if (depth > kMaxParamDepth) r.fail("parameters nested too deeply");
  const uint32_t n = r.u32("parameters");
  if (n > r.left() / 5) r.fail("bad parameter count");  // each takes at least 5 bytes
  core::Params params;
  for (uint32_t q = 0; q < n; ++q) {
    core::Param p;
    p.name = r.text("parameter name");
    switch (static_cast<ParamKind>(r.u8("parameter kind"))) {
      case ParamKind::kBool:
        p.value = r.flag("parameter");
        break;
      case ParamKind::kInt:
        p.value = static_cast<int>(r.i32("parameter"));
        break;
      case ParamKind::kDouble:
        p.value = r.f64("parameter");
        break;
      case ParamKind::kString:
        p.value = r.text("parameter");
        break;
      case ParamKind::kGroup:
        p.group = true;
        p.value = false;
        p.children = readParams(r, depth + 1);
        break;
      default:
        r.fail("unknown parameter kind");
    }
    params.push_back(std::move(p));
  }
  return params;
}

/// Fills a config from saved parameters by name; names the file lacks keep their defaults.
class ParamsReader : public core::ParameterVisitor {
 public:
  ParamsReader(const core::Params& params, Reader& r) : r_(r) {
    for (const core::Param& p : params)
      if (!p.group) values_[p.name] = p.value;
  }
  void visit(const core::ParameterInfo& i, int& v) override { get(i, v); }
  void visit(const core::ParameterInfo& i, double& v) override { get(i, v); }
  void visit(const core::ParameterInfo& i, bool& v) override { get(i, v); }
  void visit(const core::ParameterInfo& i, std::string& v) override { get(i, v); }

 private:
  template <typename T>
  void get(const core::ParameterInfo& info, T& value) {
    const auto it = values_.find(info.name);
    if (it == values_.end()) return;
    const T* saved = std::get_if<T>(&it->second);
    if (!saved) r_.fail(std::string("parameter ") + info.name + " has the wrong type");
    value = *saved;
  }
  std::map<std::string, core::Param::Value> values_;
  Reader& r_;
};

// ---------------------------------------------------------------------------------------------
// Sections.

void writeKeyframe(Writer& w, const core::Keyframe& k) {
  w.f64(k.stamp);
  w.text(k.image_name);
  writeIntrinsics(w, k.intrinsics);
  writePose(w, k.pose);
  writePoints(w, k.points);
  writeDepthMap(w, k.depth);
}
void readKeyframe(Reader& r, core::Keyframe& k) {
  k.stamp = r.finite("keyframe stamp");
  k.image_name = r.text("image name");
  k.intrinsics = readIntrinsics(r);
  k.pose = readPose(r);
  k.points = readPoints(r);
  k.depth = readDepthMap(r);
}
void writeKeyframes(Writer& w, const std::vector<core::Keyframe>& keyframes) {
  w.u64(keyframes.size());
  for (const core::Keyframe& k : keyframes) writeKeyframe(w, k);
}
std::vector<core::Keyframe> readKeyframes(Reader& r) {
  std::vector<core::Keyframe> keyframes(r.count(117, "keyframes"));
  for (core::Keyframe& k : keyframes) readKeyframe(r, k);
  return keyframes;
}

void writeRow(Writer& w, const std::vector<core::TableEntry>& row) {
  w.u64(row.size());
  for (const core::TableEntry& e : row) {
    w.i32(e.view);
    w.f64(e.value);
  }
}
void readRow(Reader& r, std::vector<core::TableEntry>& row) {
  row.resize(r.count(12, "matrix row"));
  for (core::TableEntry& e : row) {
    e.view = r.i32("matrix entry");
    e.value = r.f64("matrix entry");
  }
}
void writeRows(Writer& w, const std::vector<std::vector<core::TableEntry>>& rows) {
  w.u64(rows.size());
  for (const auto& row : rows) writeRow(w, row);
}
std::vector<std::vector<core::TableEntry>> readRows(Reader& r) {
  std::vector<std::vector<core::TableEntry>> rows(r.count(8, "matrix rows"));
  for (auto& row : rows) readRow(r, row);
  return rows;
}

void writeMapState(Writer& w, const points::MapPointSource::State& s) {
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
points::MapPointSource::State readMapState(Reader& r) {
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

void writeFeatureState(Writer& w, const points::FeaturePointSource::State& s) {
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
points::FeaturePointSource::State readFeatureState(Reader& r) {
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

void writeStatistics(Writer& w, const SessionStatistics& s) {
  w.u64(s.frames_received);
  w.u64(s.frames_offered);
  w.u64(s.dropped.size());
  for (const auto& [reason, count] : s.dropped) {
    w.text(reason);
    w.u64(count);
  }
  w.text(s.last_error);
  w.f64(s.last_error_stamp);
  w.f64(s.last_insertion_seconds);
  w.f64(s.max_insertion_seconds);
  w.flag(s.last_frame_stamp.has_value());
  w.f64(s.last_frame_stamp.value_or(0.0));
}
SessionStatistics readStatistics(Reader& r) {
  SessionStatistics s;
  s.frames_received = r.u64("statistics");
  s.frames_offered = r.u64("statistics");
  const size_t reasons = r.count(12, "drop reasons");
  for (size_t q = 0; q < reasons; ++q) {
    std::string reason = r.text("drop reason");
    s.dropped[reason] = r.u64("drop count");
  }
  s.last_error = r.text("last error");
  s.last_error_stamp = r.f64("statistics");
  s.last_insertion_seconds = r.f64("statistics");
  s.max_insertion_seconds = r.f64("statistics");
  const bool has_last = r.flag("statistics");
  const double last = r.f64("statistics");
  if (has_last) s.last_frame_stamp = last;
  return s;
}

std::string describeSource(const std::string& name, const core::Params& params) {
  std::string text = "'" + name + "' (";
  std::function<void(const core::Params&)> add = [&](const core::Params& ps) {
    for (const core::Param& p : ps) {
      if (p.group) {
        add(p.children);
        continue;
      }
      text += p.name + "=";
      std::visit(
          [&](const auto& v) {
            using T = std::decay_t<decltype(v)>;
            if constexpr (std::is_same_v<T, std::string>)
              text += v;
            else if constexpr (std::is_same_v<T, bool>)
              text += v ? "true" : "false";
            else if constexpr (std::is_same_v<T, double>)
              text += core::formatNumber(v);
            else
              text += std::to_string(v);
          },
          p.value);
      text += " ";
    }
  };
  add(params);
  if (text.back() == ' ') text.pop_back();
  return text + ")";
}

/// The feature source of "features", or of "auto"; null for the others.
points::FeaturePointSource* featuresOf(core::PointSource& source) {
  if (auto* f = dynamic_cast<points::FeaturePointSource*>(&source)) return f;
  if (auto* a = dynamic_cast<points::AutoPointSource*>(&source)) return &a->features();
  return nullptr;
}
const points::FeaturePointSource* featuresOf(const core::PointSource& source) {
  if (auto* f = dynamic_cast<const points::FeaturePointSource*>(&source)) return f;
  if (auto* a = dynamic_cast<const points::AutoPointSource*>(&source)) return &a->features();
  return nullptr;
}

}  // namespace

bool SessionStatistics::operator==(const SessionStatistics& o) const {
  return frames_received == o.frames_received && frames_offered == o.frames_offered &&
         dropped == o.dropped && last_error == o.last_error &&
         last_error_stamp == o.last_error_stamp &&
         last_insertion_seconds == o.last_insertion_seconds &&
         max_insertion_seconds == o.max_insertion_seconds && last_frame_stamp == o.last_frame_stamp;
}

uint32_t crc32(const uint8_t* data, size_t size, uint32_t crc) {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t n = 0; n < 256; ++n) {
      uint32_t c = n;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[n] = c;
    }
    return t;
  }();
  crc = ~crc;
  for (size_t q = 0; q < size; ++q) crc = table[(crc ^ data[q]) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

SessionState captureSession(const core::ViewSelector& selector) {
  SessionState s;
  s.selector = selector.state();
  const core::PointSource& source = selector.pointSource();
  s.points.name = source.name();
  s.points.params = source.params();
  if (auto* map = dynamic_cast<const points::MapPointSource*>(&source)) s.points.map = map->state();
  if (auto* features = featuresOf(source)) s.points.features = features->state();
  return s;
}

void restoreSession(core::ViewSelector& selector, const SessionState& state) {
  core::PointSource& source = selector.pointSource();
  if (state.points.name != source.name() || state.points.params != source.params())
    throw core::InvalidArgument(
        "the saved session was made with point source " +
        describeSource(state.points.name, state.points.params) + ", this one uses " +
        describeSource(source.name(), source.params()) + ": its points cannot continue here");
  try {
    selector.restore(state.selector);
    source.reset();
    if (auto* map = dynamic_cast<points::MapPointSource*>(&source)) {
      if (!state.points.map) throw core::InvalidInput("the saved session has no map");
      map->restore(*state.points.map);
    }
    if (auto* features = featuresOf(source)) {
      if (!state.points.features) throw core::InvalidInput("the saved session has no features");
      features->restore(*state.points.features);
    }
  } catch (...) {
    selector.reset();
    throw;
  }
}

namespace {

// The sections of a state (the file's content after the header; a journal record's trailer).
void encodeContent(Writer& w, const SessionState& state) {
  size_t s = w.beginSection(kSession);
  w.text(state.producer);
  w.f64(state.saved_at);
  w.endSection(s);

  s = w.beginSection(kConfig);
  writeParams(w, core::paramsOf(state.selector.config));
  w.endSection(s);

  s = w.beginSection(kKeyframes);
  writeKeyframes(w, state.selector.keyframes);
  w.endSection(s);

  s = w.beginSection(kMatrix);
  writeRows(w, state.selector.rows);
  w.endSection(s);

  s = w.beginSection(kPolicy);
  w.i64(state.selector.policy.frames_offered);
  w.flag(state.selector.policy.last_keyframe.has_value());
  writePose(w, state.selector.policy.last_keyframe.value_or(core::CameraPose{}));
  w.flag(state.selector.last_stamp.has_value());
  w.f64(state.selector.last_stamp.value_or(0.0));
  w.endSection(s);

  s = w.beginSection(kPoints);
  w.text(state.points.name);
  writeParams(w, state.points.params);
  w.flag(state.points.map.has_value());
  if (state.points.map) writeMapState(w, *state.points.map);
  w.flag(state.points.features.has_value());
  if (state.points.features) writeFeatureState(w, *state.points.features);
  w.endSection(s);

  s = w.beginSection(kStatistics);
  writeStatistics(w, state.statistics);
  w.endSection(s);

  // Optional (readers before it skip it): the pair stream's sequence, so that it continues.
  if (state.pair_sequence) {
    s = w.beginSection(kPairStream);
    w.u64(*state.pair_sequence);
    w.endSection(s);
  }
  // Optional: the id a journal's records name to follow this file.
  if (state.base_id) {
    s = w.beginSection(kJournalBase);
    w.u64(*state.base_id);
    w.endSection(s);
  }
}

SessionState decodeContent(Reader& r, const std::string& what);

}  // namespace

std::vector<uint8_t> encodeState(const SessionState& state) {
  Writer w;
  encodeContent(w, state);
  const std::vector<uint8_t>& payload = w.bytes;
  Writer h;
  h.raw(kMagic.data(), kMagic.size());
  h.u32(kStateFormatVersion);
  h.u32(static_cast<uint32_t>(kHeaderSize));
  h.u64(payload.size());
  h.u32(crc32(payload.data(), payload.size()));
  h.u32(crc32(h.bytes.data(), h.bytes.size()));
  h.raw(payload.data(), payload.size());
  return std::move(h.bytes);
}

SessionState decodeState(const uint8_t* data, size_t size, const std::string& name) {
  const std::string what = name.empty() ? "state" : "state file '" + name + "'";
  const size_t signature = std::min(size, kMagic.size());
  if (size == 0 || std::memcmp(data, kMagic.data(), signature) != 0)
    throw StateFileError(
        what + (size == 0 ? " is empty"
                          : " is not a view_selection state file (no state file signature)"));
  if (size < kHeaderSize)
    throw StateFileError(what + " is truncated: " + std::to_string(size) +
                         " bytes, shorter than the header");
  Reader header(data, kHeaderSize, what);
  header.take(kMagic.size(), "signature");
  const uint32_t version = header.u32("version");
  const uint32_t header_size = header.u32("header size");
  const uint64_t payload_size = header.u64("payload size");
  const uint32_t payload_crc = header.u32("checksum");
  const uint32_t header_crc = header.u32("header checksum");
  if (header_crc != crc32(data, kHeaderSize - 4))
    throw StateFileError(what + " is corrupted: the header's checksum does not match");
  if (version == 0 || version > kStateFormatVersion)
    throw StateFileError(what + " has format version " + std::to_string(version) +
                         "; this build reads versions 1 to " + std::to_string(kStateFormatVersion));
  if (header_size != kHeaderSize)
    throw StateFileError(what + " has a header of " + std::to_string(header_size) + " bytes");
  if (payload_size != size - kHeaderSize)
    throw StateFileError(what + " is truncated or has trailing bytes: the header says " +
                         std::to_string(payload_size) + " bytes of content, the file has " +
                         std::to_string(size - kHeaderSize));
  const uint8_t* payload = data + kHeaderSize;
  if (payload_crc != crc32(payload, static_cast<size_t>(payload_size)))
    throw StateFileError(what + " is corrupted: the content's checksum does not match");
  Reader r(payload, static_cast<size_t>(payload_size), what);
  return decodeContent(r, what);
}

namespace {

SessionState decodeContent(Reader& r, const std::string& what) {
  SessionState state;
  uint32_t seen = 0;  // bit per required section
  const std::array<uint32_t, 7> required = {kSession, kConfig, kKeyframes, kMatrix,
                                            kPolicy,  kPoints, kStatistics};
  while (!r.done()) {
    const uint32_t t = r.u32("section tag");
    const uint64_t length = r.u64("section length");
    if (length > r.left()) r.fail("truncated section");
    const std::string tag_name(reinterpret_cast<const char*>(&t), 4);
    Reader s = r.section(static_cast<size_t>(length), tag_name);
    for (size_t q = 0; q < required.size(); ++q)
      if (required[q] == t) {
        if (seen & (1u << q)) s.fail("section repeated");
        seen |= 1u << q;
      }
    if (t == kSession) {
      state.producer = s.text("producer");
      state.saved_at = s.f64("saved at");
    } else if (t == kConfig) {
      const core::Params params = readParams(s);
      ParamsReader reader(params, s);
      try {
        state.selector.config.visitParameters(reader);
        state.selector.config.validate();
      } catch (const core::InvalidArgument& e) {
        s.fail(std::string("bad parameter: ") + e.what());
      }
    } else if (t == kKeyframes) {
      state.selector.keyframes = readKeyframes(s);
    } else if (t == kMatrix) {
      state.selector.rows = readRows(s);
    } else if (t == kPolicy) {
      state.selector.policy.frames_offered = s.i64("frames offered");
      if (state.selector.policy.frames_offered < 0) s.fail("negative frame count");
      const bool has_last = s.flag("policy");
      const core::CameraPose last = readPose(s);
      if (has_last) state.selector.policy.last_keyframe = last;
      const bool has_stamp = s.flag("last stamp");
      const double stamp = s.f64("last stamp");
      if (has_stamp) {
        if (!std::isfinite(stamp)) s.fail("non-finite last stamp");
        state.selector.last_stamp = stamp;
      }
    } else if (t == kPoints) {
      state.points.name = s.text("point source");
      state.points.params = readParams(s);
      if (s.flag("map")) state.points.map = readMapState(s);
      if (s.flag("features")) state.points.features = readFeatureState(s);
    } else if (t == kStatistics) {
      state.statistics = readStatistics(s);
    } else if (t == kPairStream) {
      state.pair_sequence = s.u64("pair sequence");
    } else if (t == kJournalBase) {
      state.base_id = s.u64("journal base id");
    } else {
      continue;  // a section of a later minor revision: skipped
    }
    s.expectEnd("the section");
  }
  for (size_t q = 0; q < required.size(); ++q)
    if (!(seen & (1u << q)))
      throw StateFileError(what + " lacks its '" +
                           std::string(reinterpret_cast<const char*>(&required[q]), 4) +
                           "' section");
  if (state.selector.rows.size() != state.selector.keyframes.size())
    throw StateFileError(what + " is inconsistent: " + std::to_string(state.selector.rows.size()) +
                         " matrix rows for " + std::to_string(state.selector.keyframes.size()) +
                         " keyframes");
  return state;
}

}  // namespace

size_t writeStateFile(const std::string& path, const SessionState& state) {
  const std::vector<uint8_t> bytes = encodeState(state);
  writeAtomically(
      path, [&](const std::string& tmp) { writeFileContents(tmp, bytes.data(), bytes.size()); });
  return bytes.size();
}

std::unique_ptr<core::ViewSelector> selectorFor(const SessionState& state) {
  // The point source's parameters from the saved ones, by name (groups flattened: "auto").
  core::Params flat;
  std::function<void(const core::Params&)> add = [&](const core::Params& ps) {
    for (const core::Param& p : ps) {
      if (p.group)
        add(p.children);
      else
        flat.push_back(p);
    }
  };
  add(state.points.params);
  points::PointSourceParams params;
  Reader unused(nullptr, 0, "saved point source parameters");
  ParamsReader reader(flat, unused);
  params.visitParameters(reader);
  params.validate();
  auto selector = std::make_unique<core::ViewSelector>(
      state.selector.config,
      points::makePointSource(state.points.name, params, state.selector.config.matrix.occlusion));
  restoreSession(*selector, state);
  return selector;
}

SessionState readStateFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw core::IoError("cannot open '" + path + "': " + std::strerror(errno));
  std::vector<uint8_t> bytes;
  uint8_t buffer[1 << 16];
  while (true) {
    const ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int saved = errno;
      ::close(fd);
      throw core::IoError("cannot read '" + path + "': " + std::strerror(saved));
    }
    if (n == 0) break;
    bytes.insert(bytes.end(), buffer, buffer + n);
  }
  ::close(fd);
  return decodeState(bytes.data(), bytes.size(), path);
}

std::string moveAside(const std::string& path) {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%S", &utc);
  const std::string base = path + ".bad-" + stamp;
  for (int n = 0; n < 1000; ++n) {
    const std::string candidate = n == 0 ? base : base + "-" + std::to_string(n);
    // Never over an existing file (rename() would replace it).
    if (::renameat2(AT_FDCWD, path.c_str(), AT_FDCWD, candidate.c_str(), RENAME_NOREPLACE) == 0)
      return candidate;
    // File systems without RENAME_NOREPLACE: a hard link fails on an existing name too.
    if (errno == EINVAL && ::link(path.c_str(), candidate.c_str()) == 0) {
      ::unlink(path.c_str());
      return candidate;
    }
    if (errno != EEXIST)
      throw core::IoError("cannot keep '" + path + "' aside as '" + candidate +
                          "': " + std::strerror(errno));
  }
  throw core::IoError("cannot keep '" + path + "' aside: too many earlier bad copies");
}

// ---------------------------------------------------------------------------------------------
// The journal (docs/state_file.md, "The journal").

namespace {

constexpr std::array<uint8_t, 4> kJournalMagic = {'V', 'S', 'J', 'R'};
constexpr uint32_t kJournalVersion = 1;
constexpr size_t kRecordHeaderSize = 24;

/// The trailer of a record: `rest` without keyframes and rows (whatever it holds).
SessionState trailerOf(const SessionState& rest) {
  SessionState t;
  t.producer = rest.producer;
  t.saved_at = rest.saved_at;
  t.selector.config = rest.selector.config;
  t.selector.policy = rest.selector.policy;
  t.selector.last_stamp = rest.selector.last_stamp;
  t.points = rest.points;
  t.statistics = rest.statistics;
  t.pair_sequence = rest.pair_sequence;
  return t;
}

SessionDelta decodeRecord(Reader& r, uint64_t& base_id, uint64_t& index, const std::string& what) {
  SessionDelta d;
  base_id = r.u64("base id");
  index = r.u64("record index");
  d.keyframe_count = r.u64("keyframe count");
  d.keyframes.resize(r.count(4 + 117, "changed keyframes"));
  for (auto& [id, k] : d.keyframes) {
    id = r.i32("keyframe id");
    readKeyframe(r, k);
  }
  d.rows.resize(r.count(4 + 8, "changed rows"));
  for (auto& [id, row] : d.rows) {
    id = r.i32("row id");
    readRow(r, row);
  }
  d.rest = decodeContent(r, what);
  return d;
}

}  // namespace

void applyDelta(SessionState& state, const SessionDelta& delta) {
  const auto fail = [](const std::string& why) {
    throw StateFileError("journal record does not fit its state: " + why);
  };
  const uint64_t n = delta.keyframe_count;
  const size_t before = std::min<size_t>(state.selector.keyframes.size(), n);
  // Every new keyframe and row must be in the record; every id in range, ascending.
  const auto check = [&](const auto& list, const char* what) {
    uint64_t next_new = before;
    int64_t last = -1;
    for (const auto& [id, value] : list) {
      if (id < 0 || static_cast<uint64_t>(id) >= n || id <= last)
        fail(std::string(what) + " id " + std::to_string(id) + " out of range or order");
      last = id;
      if (static_cast<uint64_t>(id) >= before) {
        if (static_cast<uint64_t>(id) != next_new) fail(std::string("new ") + what + " missing");
        ++next_new;
      }
    }
    if (next_new != n) fail(std::string("new ") + what + " missing");
  };
  check(delta.keyframes, "keyframe");
  check(delta.rows, "row");
  state.selector.keyframes.resize(n);
  state.selector.rows.resize(n);
  for (const auto& [id, k] : delta.keyframes) state.selector.keyframes[static_cast<size_t>(id)] = k;
  for (const auto& [id, row] : delta.rows) state.selector.rows[static_cast<size_t>(id)] = row;
  const SessionState& t = delta.rest;
  state.producer = t.producer;
  state.saved_at = t.saved_at;
  state.selector.config = t.selector.config;
  state.selector.policy = t.selector.policy;
  state.selector.last_stamp = t.selector.last_stamp;
  state.points = t.points;
  state.statistics = t.statistics;
  state.pair_sequence = t.pair_sequence;
}

void mergeDelta(SessionDelta& earlier, SessionDelta later) {
  const auto merge = [&](auto& a, auto& b) {
    // Both ascending by id: later's entries win; ids at or beyond the new count go.
    std::decay_t<decltype(a)> out;
    out.reserve(a.size() + b.size());
    size_t p = 0, q = 0;
    while (p < a.size() || q < b.size()) {
      if (q == b.size() || (p < a.size() && a[p].first < b[q].first)) {
        if (static_cast<uint64_t>(a[p].first) < later.keyframe_count) out.push_back(std::move(a[p]));
        ++p;
      } else {
        if (p < a.size() && a[p].first == b[q].first) ++p;
        out.push_back(std::move(b[q++]));
      }
    }
    a = std::move(out);
  };
  merge(earlier.keyframes, later.keyframes);
  merge(earlier.rows, later.rows);
  earlier.keyframe_count = later.keyframe_count;
  earlier.rest = std::move(later.rest);
}

void DeltaTracker::markSaved(const core::ViewSelector& selector) {
  saved_ = selector.matrix().size();
  row_mark_ = core::ErrorResistanceTable::lastVersionIssued();
  keyframe_mark_ = core::ErrorResistanceMatrix::lastKeyframeVersionIssued();
}

SessionDelta DeltaTracker::capture(const core::ViewSelector& selector) {
  const core::ErrorResistanceMatrix& m = selector.matrix();
  const core::ErrorResistanceTable& table = m.table();
  const size_t n = m.size();
  const uint64_t row_mark = core::ErrorResistanceTable::lastVersionIssued();
  const uint64_t keyframe_mark = core::ErrorResistanceMatrix::lastKeyframeVersionIssued();
  SessionDelta d;
  d.keyframe_count = n;
  constexpr size_t kChunk = core::ErrorResistanceTable::kVersionChunk;
  const size_t saved = std::min(n, saved_);  // new ones from here on, always
  for (size_t c = 0; c * kChunk < n; ++c) {
    const size_t end = std::min(n, (c + 1) * kChunk);
    if (end <= saved && table.chunkVersion(c) <= row_mark_ &&
        m.keyframeChunkVersion(c) <= keyframe_mark_)
      continue;  // nothing in it changed
    for (size_t i = c * kChunk; i < end; ++i) {
      const auto id = static_cast<core::ViewId>(i);
      if (i >= saved || m.keyframeVersion(id) > keyframe_mark_)
        d.keyframes.emplace_back(id, m.keyframe(id));
      if (i >= saved || table.rowVersion(id) > row_mark_) d.rows.emplace_back(id, table.row(id));
    }
  }
  saved_ = n;
  row_mark_ = row_mark;
  keyframe_mark_ = keyframe_mark;
  const core::PointSource& source = selector.pointSource();
  d.rest.selector.config = selector.config();
  d.rest.selector.policy = selector.policyState();
  d.rest.selector.last_stamp = selector.lastStamp();
  d.rest.points.name = source.name();
  d.rest.points.params = source.params();
  if (auto* map = dynamic_cast<const points::MapPointSource*>(&source)) d.rest.points.map = map->state();
  if (auto* features = featuresOf(source)) d.rest.points.features = features->state();
  return d;
}

std::vector<uint8_t> encodeJournalRecord(uint64_t base_id, uint64_t index,
                                         const SessionDelta& delta) {
  Writer w;
  w.u64(base_id);
  w.u64(index);
  w.u64(delta.keyframe_count);
  w.u64(delta.keyframes.size());
  for (const auto& [id, k] : delta.keyframes) {
    w.i32(id);
    writeKeyframe(w, k);
  }
  w.u64(delta.rows.size());
  for (const auto& [id, row] : delta.rows) {
    w.i32(id);
    writeRow(w, row);
  }
  encodeContent(w, trailerOf(delta.rest));
  Writer h;
  h.raw(kJournalMagic.data(), kJournalMagic.size());
  h.u32(kJournalVersion);
  h.u64(w.bytes.size());
  h.u32(crc32(w.bytes.data(), w.bytes.size()));
  h.u32(crc32(h.bytes.data(), h.bytes.size()));
  h.raw(w.bytes.data(), w.bytes.size());
  return std::move(h.bytes);
}

JournalReplay replayJournal(SessionState& state, const uint8_t* data, size_t size,
                            const std::string& name) {
  JournalReplay out;
  out.total_bytes = size;
  const std::string what = name.empty() ? "journal" : "journal '" + name + "'";
  size_t pos = 0;
  uint64_t expected = 0;  // the next record index of this base
  while (pos < size) {
    const auto stop = [&](const std::string& why) {
      out.error = what + ": " + why + " at byte " + std::to_string(pos) + " (record " +
                  std::to_string(out.records + out.stale) + "); the " + std::to_string(size - pos) +
                  " bytes from there on are dropped";
    };
    if (size - pos < kRecordHeaderSize) {
      stop("a torn record header");
      break;
    }
    const uint8_t* h = data + pos;
    Reader header(h, kRecordHeaderSize, what);
    if (std::memcmp(header.take(4, "signature"), kJournalMagic.data(), 4) != 0) {
      stop("no record signature");
      break;
    }
    const uint32_t version = header.u32("version");
    const uint64_t length = header.u64("record length");
    const uint32_t payload_crc = header.u32("record checksum");
    const uint32_t header_crc = header.u32("record header checksum");
    if (header_crc != crc32(h, kRecordHeaderSize - 4)) {
      stop("a record header whose checksum does not match");
      break;
    }
    if (version != kJournalVersion) {
      stop("a record of version " + std::to_string(version));
      break;
    }
    if (length > size - pos - kRecordHeaderSize) {
      stop("a torn record (" + std::to_string(length) + " bytes announced, " +
           std::to_string(size - pos - kRecordHeaderSize) + " there)");
      break;
    }
    const uint8_t* payload = h + kRecordHeaderSize;
    if (payload_crc != crc32(payload, static_cast<size_t>(length))) {
      stop("a record whose checksum does not match");
      break;
    }
    try {
      Reader r(payload, static_cast<size_t>(length), what);
      uint64_t base_id = 0, index = 0;
      SessionDelta delta = decodeRecord(r, base_id, index, what);
      if (!state.base_id || base_id != *state.base_id) {
        ++out.stale;  // of an earlier base: the base holds it already
      } else {
        if (index != expected)
          throw StateFileError("record " + std::to_string(index) + " where " +
                               std::to_string(expected) + " was due");
        applyDelta(state, delta);
        ++expected;
        ++out.records;
      }
    } catch (const core::Error& e) {
      stop(e.what());
      break;
    }
    pos += kRecordHeaderSize + static_cast<size_t>(length);
    out.good_bytes = pos;
  }
  return out;
}

std::string journalPath(const std::string& path) { return path + ".journal"; }

namespace {

std::vector<uint8_t> readWholeFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw core::IoError("cannot open '" + path + "': " + std::strerror(errno));
  std::vector<uint8_t> bytes;
  uint8_t buffer[1 << 16];
  while (true) {
    const ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int saved = errno;
      ::close(fd);
      throw core::IoError("cannot read '" + path + "': " + std::strerror(saved));
    }
    if (n == 0) break;
    bytes.insert(bytes.end(), buffer, buffer + n);
  }
  ::close(fd);
  return bytes;
}

}  // namespace

SessionState readSession(const std::string& path, JournalReplay* replay) {
  SessionState state = readStateFile(path);
  const std::string journal = journalPath(path);
  JournalReplay r;
  if (::access(journal.c_str(), F_OK) == 0) {
    const std::vector<uint8_t> bytes = readWholeFile(journal);
    r = replayJournal(state, bytes.data(), bytes.size(), journal);
  }
  if (replay) *replay = r;
  return state;
}

void appendToFile(const std::string& path, const std::vector<uint8_t>& bytes) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw core::IoError("cannot open '" + path + "': " + std::strerror(errno));
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int saved = errno;
      ::close(fd);
      throw core::IoError("cannot append to '" + path + "': " + std::strerror(saved));
    }
    done += static_cast<size_t>(n);
  }
  if (::fdatasync(fd) != 0) {
    const int saved = errno;
    ::close(fd);
    throw core::IoError("cannot flush '" + path + "': " + std::strerror(saved));
  }
  ::close(fd);
}

void truncateFile(const std::string& path, size_t size) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw core::IoError("cannot open '" + path + "': " + std::strerror(errno));
  if (::ftruncate(fd, static_cast<off_t>(size)) != 0 || ::fsync(fd) != 0) {
    const int saved = errno;
    ::close(fd);
    throw core::IoError("cannot truncate '" + path + "': " + std::strerror(saved));
  }
  ::close(fd);
}

}  // namespace view_selection::io
