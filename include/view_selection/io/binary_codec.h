// Little-endian binary writing and reading for the state file and its journal
// (docs/state_file.md: the types), with the core's types they hold: intrinsics, poses, points,
// depth maps, parameters. Every read is bounded by what is left, so no input makes a reader read
// past its end or allocate more than the input could hold; a read that fails throws
// StateFileError saying what and where.
#pragma once

#include "view_selection/core/exceptions.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace view_selection::io {

/// A state file (or a journal record) that cannot be used: truncated, corrupted, foreign, or of
/// a newer format. The message says which, and names the file when it came from one.
class StateFileError : public core::IoError {
 public:
  using core::IoError::IoError;
};

class BinaryWriter {
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

  /// Starts a section (u32 tag, u64 length); end it with endSection(start).
  size_t beginSection(uint32_t tag);
  void endSection(size_t at);
};

class BinaryReader {
 public:
  /// `context` starts every error message (e.g. "state file 'x'").
  BinaryReader(const uint8_t* data, size_t size, std::string context)
      : data_(data), size_(size), context_(std::move(context)) {}

  [[noreturn]] void fail(const std::string& what) const;
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
  /// An f64 that must be finite.
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
  size_t count(size_t element_bytes, const char* what);
  /// The next `length` bytes as a reader of their own, named `name` in its errors.
  BinaryReader section(size_t length, const std::string& name);
  void expectEnd(const char* what) const;

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  std::string context_;
};

/// Four ASCII bytes as a section tag.
constexpr uint32_t sectionTag(const char (&t)[5]) {
  return static_cast<uint32_t>(static_cast<uint8_t>(t[0])) |
         static_cast<uint32_t>(static_cast<uint8_t>(t[1])) << 8 |
         static_cast<uint32_t>(static_cast<uint8_t>(t[2])) << 16 |
         static_cast<uint32_t>(static_cast<uint8_t>(t[3])) << 24;
}

// The core's types (docs/state_file.md: `intrinsics`, `pose`, `points`, `depth map`, `params`).
// Readers check what they read (valid intrinsics and poses, finite points, a consistent depth
// map) and fail otherwise.

void writeIntrinsics(BinaryWriter& w, const core::PinholeIntrinsics& k);
core::PinholeIntrinsics readIntrinsics(BinaryReader& r);
void writePose(BinaryWriter& w, const core::CameraPose& p);
core::CameraPose readPose(BinaryReader& r);
void writePoints(BinaryWriter& w, const Eigen::Matrix3Xd& points);
Eigen::Matrix3Xd readPoints(BinaryReader& r);
void writeDepthMap(BinaryWriter& w, const std::shared_ptr<const core::DepthMap>& map);
std::shared_ptr<const core::DepthMap> readDepthMap(BinaryReader& r);
void writeParams(BinaryWriter& w, const core::Params& params);
core::Params readParams(BinaryReader& r);

/// Fills a config from saved parameters by name; names the saved ones lack keep their
/// defaults, a saved one of the wrong type fails `r`.
class ParamsReader : public core::ParameterVisitor {
 public:
  ParamsReader(const core::Params& params, BinaryReader& r);
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
  BinaryReader& r_;
};

}  // namespace view_selection::io
