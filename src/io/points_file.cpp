#include "view_selection/io/points_file.h"

#include "view_selection/core/exceptions.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <vector>

namespace view_selection::io {

namespace {

constexpr char kMagic[8] = {'V', 'S', 'P', 'O', 'I', 'N', 'T', 'S'};
constexpr uint32_t kVersion = 1;
constexpr uint32_t kMaxPoints = 1u << 24;  // per keyframe; more is a damaged file

}  // namespace

PointsFileWriter::PointsFileWriter(const std::string& path, const core::PinholeIntrinsics& k,
                                   uint64_t keyframes)
    : path_(path), expected_(keyframes) {
  file_ = std::fopen(path.c_str(), "wb");
  if (!file_) throw core::IoError("cannot write '" + path + "': " + std::strerror(errno));
  const uint32_t version = kVersion, reserved = 0;
  const double intrinsics[4] = {k.fx, k.fy, k.cx, k.cy};
  const int32_t size[2] = {k.width, k.height};
  put(kMagic, sizeof kMagic);
  put(&version, sizeof version);
  put(&reserved, sizeof reserved);
  put(&keyframes, sizeof keyframes);
  put(intrinsics, sizeof intrinsics);
  put(size, sizeof size);
}

PointsFileWriter::~PointsFileWriter() {
  if (file_) std::fclose(file_);
}

void PointsFileWriter::put(const void* data, size_t size) {
  if (std::fwrite(data, 1, size, file_) != size)
    throw core::IoError("cannot write '" + path_ + "': " + std::strerror(errno));
}

void PointsFileWriter::write(const PointsRecord& r) {
  const double head[8] = {r.stamp,
                          r.pose.position.x(),
                          r.pose.position.y(),
                          r.pose.position.z(),
                          r.pose.orientation.x(),
                          r.pose.orientation.y(),
                          r.pose.orientation.z(),
                          r.pose.orientation.w()};
  put(head, sizeof head);
  const auto n = static_cast<uint32_t>(r.points.cols());
  put(&n, sizeof n);
  std::vector<float> xyz(static_cast<size_t>(n) * 3);
  for (uint32_t q = 0; q < n; ++q)
    for (int a = 0; a < 3; ++a) xyz[q * 3 + static_cast<uint32_t>(a)] = static_cast<float>(r.points(a, q));
  put(xyz.data(), xyz.size() * sizeof(float));
  ++written_;
}

void PointsFileWriter::close() {
  if (!file_) return;
  std::FILE* f = file_;
  file_ = nullptr;
  const bool flushed = std::fflush(f) == 0;
  const int e = errno;
  if (std::fclose(f) != 0 || !flushed)
    throw core::IoError("cannot write '" + path_ + "': " + std::strerror(flushed ? errno : e));
  if (written_ != expected_)
    throw core::IoError("'" + path_ + "' promised " + std::to_string(expected_) +
                        " keyframes but " + std::to_string(written_) + " were written");
}

PointsFileReader::PointsFileReader(const std::string& path) : path_(path) {
  file_ = std::fopen(path.c_str(), "rb");
  if (!file_) throw core::IoError("cannot read '" + path + "': " + std::strerror(errno));
  char magic[8];
  get(magic, sizeof magic, "header");
  if (std::memcmp(magic, kMagic, sizeof magic) != 0)
    throw core::InvalidInput("'" + path + "' is not a points.bin file (no VSPOINTS header)");
  uint32_t version = 0, reserved = 0;
  get(&version, sizeof version, "header");
  get(&reserved, sizeof reserved, "header");
  if (version != kVersion)
    throw core::InvalidInput("'" + path + "' is points.bin version " + std::to_string(version) +
                             "; this reader knows version 1");
  get(&count_, sizeof count_, "header");
  double k[4];
  int32_t size[2];
  get(k, sizeof k, "header");
  get(size, sizeof size, "header");
  intrinsics_.fx = k[0];
  intrinsics_.fy = k[1];
  intrinsics_.cx = k[2];
  intrinsics_.cy = k[3];
  intrinsics_.width = size[0];
  intrinsics_.height = size[1];
  if (!intrinsics_.isValid())
    throw core::InvalidInput("'" + path + "' has unusable intrinsics");
}

PointsFileReader::~PointsFileReader() {
  if (file_) std::fclose(file_);
}

void PointsFileReader::get(void* data, size_t size, const char* what) {
  if (std::fread(data, 1, size, file_) == size) return;
  if (std::ferror(file_))
    throw core::IoError("cannot read '" + path_ + "': " + std::strerror(errno));
  throw core::InvalidInput("'" + path_ + "' ends inside the " + what + " of keyframe " +
                           std::to_string(read_) + " (truncated?)");
}

bool PointsFileReader::next(PointsRecord& r) {
  if (read_ >= count_) return false;
  double head[8];
  get(head, sizeof head, "pose");
  r.stamp = head[0];
  r.pose.position = {head[1], head[2], head[3]};
  r.pose.orientation = Eigen::Quaterniond(head[7], head[4], head[5], head[6]);
  uint32_t n = 0;
  get(&n, sizeof n, "point count");
  if (n > kMaxPoints)
    throw core::InvalidInput("'" + path_ + "': keyframe " + std::to_string(read_) + " claims " +
                             std::to_string(n) + " points");
  std::vector<float> xyz(static_cast<size_t>(n) * 3);
  get(xyz.data(), xyz.size() * sizeof(float), "points");
  r.points.resize(3, n);
  for (uint32_t q = 0; q < n; ++q)
    for (int a = 0; a < 3; ++a) r.points(a, q) = xyz[q * 3 + static_cast<uint32_t>(a)];
  ++read_;
  return true;
}

}  // namespace view_selection::io
