// points.bin: a keyframe sequence as poses and sample points only, no images (what
// `generate_sequence --points-only` writes and `select_views` reads), for runs at 100k keyframes
// where rendering and reading images would dominate. Little-endian, streamed both ways:
//   header: "VSPOINTS" (8 bytes), uint32 version (1), uint32 reserved (0), uint64 keyframes,
//           float64 fx fy cx cy, int32 width height
//   each keyframe: float64 stamp, float64 tx ty tz qx qy qz qw (camera-to-world, optical frame,
//           as groundtruth.txt), uint32 n, then n x (float32 x y z) world points [m]
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <cstdint>
#include <cstdio>
#include <string>

namespace view_selection::io {

struct PointsRecord {
  double stamp = 0.0;
  core::CameraPose pose;
  Eigen::Matrix3Xd points;  ///< world coordinates (stored as float32)
};

/// Writes points.bin record by record. Throws core::IoError with the system's reason.
class PointsFileWriter {
 public:
  PointsFileWriter(const std::string& path, const core::PinholeIntrinsics& intrinsics,
                   uint64_t keyframes);
  ~PointsFileWriter();  ///< closes without checking; call close() to know it worked
  PointsFileWriter(const PointsFileWriter&) = delete;
  PointsFileWriter& operator=(const PointsFileWriter&) = delete;
  void write(const PointsRecord& record);
  /// Flushes and closes; throws core::IoError when the records written are not the count
  /// promised or the file could not be completed.
  void close();

 private:
  void put(const void* data, size_t size);
  std::string path_;
  std::FILE* file_ = nullptr;
  uint64_t expected_ = 0, written_ = 0;
};

/// Reads points.bin record by record. Throws core::InvalidInput (bad content) or
/// core::IoError (cannot read), naming the file.
class PointsFileReader {
 public:
  explicit PointsFileReader(const std::string& path);
  ~PointsFileReader();
  PointsFileReader(const PointsFileReader&) = delete;
  PointsFileReader& operator=(const PointsFileReader&) = delete;
  uint64_t size() const { return count_; }
  const core::PinholeIntrinsics& intrinsics() const { return intrinsics_; }
  /// The next record; false after the last one.
  bool next(PointsRecord& record);

 private:
  void get(void* data, size_t size, const char* what);
  std::string path_;
  std::FILE* file_ = nullptr;
  uint64_t count_ = 0, read_ = 0;
  core::PinholeIntrinsics intrinsics_;
};

}  // namespace view_selection::io
