#include "view_selection/io/binary_codec.h"

#include <type_traits>

namespace view_selection::io {

namespace {

constexpr int kMaxImageSide = 1 << 20;  // [px] a saved width or height beyond this is corrupt
constexpr int kMaxParamDepth = 8;

enum class ParamKind : uint8_t { kBool = 0, kInt = 1, kDouble = 2, kString = 3, kGroup = 4 };

core::Params readParams(BinaryReader& r, int depth) {
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

}  // namespace

size_t BinaryWriter::beginSection(uint32_t tag) {
  u32(tag);
  const size_t at = bytes.size();
  u64(0);
  return at;
}

void BinaryWriter::endSection(size_t at) {
  const uint64_t length = bytes.size() - at - 8;
  for (int b = 0; b < 8; ++b)
    bytes[at + static_cast<size_t>(b)] = static_cast<uint8_t>(length >> (8 * b));
}

void BinaryReader::fail(const std::string& what) const {
  throw StateFileError(context_ + ": " + what + " (at byte " + std::to_string(pos_) + ")");
}

size_t BinaryReader::count(size_t element_bytes, const char* what) {
  const uint64_t n = u64(what);
  if (element_bytes > 0 && n > left() / element_bytes) fail(std::string("bad count in ") + what);
  return static_cast<size_t>(n);
}

BinaryReader BinaryReader::section(size_t length, const std::string& name) {
  const uint8_t* p = take(length, name.c_str());
  return BinaryReader(p, length, context_ + ", section " + name);
}

void BinaryReader::expectEnd(const char* what) const {
  if (!done()) fail(std::to_string(left()) + " unexpected bytes at the end of " + what);
}

void writeIntrinsics(BinaryWriter& w, const core::PinholeIntrinsics& k) {
  w.f64(k.fx);
  w.f64(k.fy);
  w.f64(k.cx);
  w.f64(k.cy);
  w.i32(k.width);
  w.i32(k.height);
}

core::PinholeIntrinsics readIntrinsics(BinaryReader& r) {
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

void writePose(BinaryWriter& w, const core::CameraPose& p) {
  for (int c = 0; c < 3; ++c) w.f64(p.position[c]);
  w.f64(p.orientation.x());
  w.f64(p.orientation.y());
  w.f64(p.orientation.z());
  w.f64(p.orientation.w());
}

core::CameraPose readPose(BinaryReader& r) {
  core::CameraPose p;
  for (int c = 0; c < 3; ++c) p.position[c] = r.f64("pose");
  const double x = r.f64("pose"), y = r.f64("pose"), z = r.f64("pose"), w = r.f64("pose");
  p.orientation = Eigen::Quaterniond(w, x, y, z);
  if (!p.isValid()) r.fail("invalid pose");
  return p;
}

void writePoints(BinaryWriter& w, const Eigen::Matrix3Xd& points) {
  w.u64(static_cast<uint64_t>(points.cols()));
  for (Eigen::Index c = 0; c < points.cols(); ++c)
    for (int d = 0; d < 3; ++d) w.f64(points(d, c));
}

Eigen::Matrix3Xd readPoints(BinaryReader& r) {
  const size_t n = r.count(24, "points");
  Eigen::Matrix3Xd points(3, static_cast<Eigen::Index>(n));
  for (size_t c = 0; c < n; ++c)
    for (int d = 0; d < 3; ++d) points(d, static_cast<Eigen::Index>(c)) = r.finite("point");
  return points;
}

void writeDepthMap(BinaryWriter& w, const std::shared_ptr<const core::DepthMap>& map) {
  w.flag(map != nullptr);
  if (!map) return;
  w.i32(map->cols);
  w.i32(map->rows);
  w.f64(map->cell_width);
  w.f64(map->cell_height);
  w.u64(map->depth.size());
  for (const float d : map->depth) w.f32(d);
}

std::shared_ptr<const core::DepthMap> readDepthMap(BinaryReader& r) {
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

void writeParams(BinaryWriter& w, const core::Params& params) {
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

core::Params readParams(BinaryReader& r) { return readParams(r, 0); }

ParamsReader::ParamsReader(const core::Params& params, BinaryReader& r) : r_(r) {
  for (const core::Param& p : params)
    if (!p.group) values_[p.name] = p.value;
}

}  // namespace view_selection::io
