#include "view_selection/io/colmap_model.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/atomic_file.h"
#include "view_selection/io/file_ops.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <numeric>

namespace view_selection::io {

namespace fs = std::filesystem;

size_t ColmapModel::observations() const {
  size_t n = 0;
  for (const auto& [id, p] : points) n += p.track.size();
  return n;
}

double ColmapModel::meanReprojectionError() const {
  double sum = 0.0;
  size_t n = 0;
  for (const auto& [id, p] : points)
    if (p.error >= 0.0) {
      sum += p.error;
      ++n;
    }
  return n ? sum / static_cast<double>(n) : 0.0;
}

int colmapCameraParameterCount(int model_id) {
  // SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE, FULL_OPENCV, FOV,
  // SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE, THIN_PRISM_FISHEYE
  static const int counts[] = {3, 4, 4, 5, 8, 8, 12, 5, 4, 5, 12};
  if (model_id < 0 || model_id >= static_cast<int>(std::size(counts)))
    throw core::IoError("unknown COLMAP camera model id " + std::to_string(model_id));
  return counts[model_id];
}

namespace {

/// Little-endian reads from a whole file in memory, with the file named in every error.
class Reader {
 public:
  explicit Reader(const fs::path& path) : path_(path.string()) {
    try {
      data_ = readFileBytes(path_);  // in 64 KB reads, not a character at a time through a stream
    } catch (const core::IoError& e) {
      throw core::IoError(std::string(e.what()) + " (a COLMAP binary model needs it)");
    }
  }

  template <typename T>
  T take() {
    if (at_ + sizeof(T) > data_.size())
      throw core::IoError(path_ + ": ends early at byte " + std::to_string(at_));
    T value;
    std::memcpy(&value, data_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return value;
  }

  std::string name() {
    const auto end = std::find(data_.begin() + static_cast<std::ptrdiff_t>(at_), data_.end(), uint8_t{0});
    if (end == data_.end()) throw core::IoError(path_ + ": an image name without its end");
    std::string s(data_.begin() + static_cast<std::ptrdiff_t>(at_), end);
    at_ = static_cast<size_t>(end - data_.begin()) + 1;
    return s;
  }

  /// A count read from the file, checked against what is left of it (each item at least
  /// `min_item_bytes`), so a corrupt count cannot ask for gigabytes.
  uint64_t count(size_t min_item_bytes) {
    const uint64_t n = take<uint64_t>();
    if (min_item_bytes > 0 && n > (data_.size() - at_) / min_item_bytes)
      throw core::IoError(path_ + ": a count of " + std::to_string(n) +
                          " items does not fit in the file");
    return n;
  }

  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::vector<uint8_t> data_;
  size_t at_ = 0;
};

class Writer {
 public:
  template <typename T>
  void put(const T& value) {
    const char* p = reinterpret_cast<const char*>(&value);
    data_.append(p, sizeof(T));
  }
  void name(const std::string& s) {
    data_.append(s);
    data_.push_back('\0');
  }
  const std::string& data() const { return data_; }

 private:
  std::string data_;
};

}  // namespace

ColmapModel readColmapModel(const std::string& folder) {
  const fs::path root(folder);
  for (const char* name : {"cameras.bin", "images.bin", "points3D.bin"})
    if (!fs::is_regular_file(root / name))
      throw core::IoError(folder + " holds no binary COLMAP model (" + name +
                          " is missing; `colmap model_converter --output_type BIN` makes one)");
  ColmapModel model;
  {
    Reader r(root / "cameras.bin");
    const uint64_t n = r.count(24);
    for (uint64_t q = 0; q < n; ++q) {
      ColmapCamera c;
      c.id = r.take<int32_t>();
      c.model_id = r.take<int32_t>();
      c.width = r.take<uint64_t>();
      c.height = r.take<uint64_t>();
      const int count = colmapCameraParameterCount(c.model_id);
      for (int k = 0; k < count; ++k) c.params.push_back(r.take<double>());
      model.cameras[c.id] = c;
    }
  }
  {
    Reader r(root / "images.bin");
    const uint64_t n = r.count(64);
    for (uint64_t q = 0; q < n; ++q) {
      ColmapImage im;
      im.id = r.take<int32_t>();
      const double qw = r.take<double>(), qx = r.take<double>(), qy = r.take<double>(),
                   qz = r.take<double>();
      im.rotation = Eigen::Quaterniond(qw, qx, qy, qz);
      if (!(im.rotation.norm() > 0.0))
        throw core::IoError(r.path() + ": image " + std::to_string(im.id) + " has a zero quaternion");
      im.rotation.normalize();
      for (int k = 0; k < 3; ++k) im.translation[k] = r.take<double>();
      im.camera_id = r.take<int32_t>();
      im.name = r.name();
      const uint64_t points = r.count(24);
      im.points2D.resize(points);
      for (auto& p : im.points2D) {
        p.xy.x() = r.take<double>();
        p.xy.y() = r.take<double>();
        p.point3D_id = static_cast<int64_t>(r.take<uint64_t>());  // kInvalidPoint3DId wraps to -1
      }
      if (!model.cameras.count(im.camera_id))
        throw core::IoError(r.path() + ": image " + im.name + " names camera " +
                            std::to_string(im.camera_id) + ", which cameras.bin does not have");
      model.images[im.id] = std::move(im);
    }
  }
  {
    Reader r(root / "points3D.bin");
    const uint64_t n = r.count(43);
    for (uint64_t q = 0; q < n; ++q) {
      ColmapPoint3D p;
      p.id = static_cast<int64_t>(r.take<uint64_t>());
      for (int k = 0; k < 3; ++k) p.xyz[k] = r.take<double>();
      for (int k = 0; k < 3; ++k) p.rgb[static_cast<size_t>(k)] = r.take<uint8_t>();
      p.error = r.take<double>();
      const uint64_t length = r.count(8);
      p.track.resize(length);
      for (auto& e : p.track) {
        e.image_id = r.take<int32_t>();
        e.point2D_idx = r.take<int32_t>();
        const auto image = model.images.find(e.image_id);
        if (image == model.images.end() || e.point2D_idx < 0 ||
            static_cast<size_t>(e.point2D_idx) >= image->second.points2D.size())
          throw core::IoError(r.path() + ": point " + std::to_string(p.id) +
                              " observes a 2D point that images.bin does not have (image " +
                              std::to_string(e.image_id) + ", index " +
                              std::to_string(e.point2D_idx) + ")");
      }
      model.points[p.id] = std::move(p);
    }
  }
  return model;
}

bool linkColmapModel(const std::string& from, const std::string& folder) {
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) return false;
  std::vector<fs::path> made;
  for (const char* name : {"cameras.bin", "images.bin", "points3D.bin"}) {
    const fs::path to = fs::path(folder) / name;
    fs::create_hard_link(fs::path(from) / name, to, ec);
    if (ec) {
      for (const fs::path& p : made) fs::remove(p, ec);
      return false;
    }
    made.push_back(to);
  }
  syncFolder(folder);
  return true;
}

void writeColmapModel(const ColmapModel& model, const std::string& folder) {
  fs::create_directories(folder);
  {
    Writer w;
    w.put<uint64_t>(model.cameras.size());
    for (const auto& [id, c] : model.cameras) {
      w.put<int32_t>(c.id);
      w.put<int32_t>(c.model_id);
      w.put<uint64_t>(c.width);
      w.put<uint64_t>(c.height);
      for (double v : c.params) w.put<double>(v);
    }
    writeAtomically((fs::path(folder) / "cameras.bin").string(),
                    [&](const std::string& tmp) { writeFileContents(tmp, w.data()); });
  }
  {
    Writer w;
    w.put<uint64_t>(model.images.size());
    for (const auto& [id, im] : model.images) {
      w.put<int32_t>(im.id);
      const Eigen::Quaterniond q = im.rotation.normalized();
      for (double v : {q.w(), q.x(), q.y(), q.z()}) w.put<double>(v);
      for (int k = 0; k < 3; ++k) w.put<double>(im.translation[k]);
      w.put<int32_t>(im.camera_id);
      w.name(im.name);
      w.put<uint64_t>(im.points2D.size());
      for (const auto& p : im.points2D) {
        w.put<double>(p.xy.x());
        w.put<double>(p.xy.y());
        w.put<uint64_t>(static_cast<uint64_t>(p.point3D_id));
      }
    }
    writeAtomically((fs::path(folder) / "images.bin").string(),
                    [&](const std::string& tmp) { writeFileContents(tmp, w.data()); });
  }
  {
    Writer w;
    w.put<uint64_t>(model.points.size());
    for (const auto& [id, p] : model.points) {
      w.put<uint64_t>(static_cast<uint64_t>(p.id));
      for (int k = 0; k < 3; ++k) w.put<double>(p.xyz[k]);
      for (uint8_t c : p.rgb) w.put<uint8_t>(c);
      w.put<double>(p.error);
      w.put<uint64_t>(p.track.size());
      for (const auto& e : p.track) {
        w.put<int32_t>(e.image_id);
        w.put<int32_t>(e.point2D_idx);
      }
    }
    writeAtomically((fs::path(folder) / "points3D.bin").string(),
                    [&](const std::string& tmp) { writeFileContents(tmp, w.data()); });
  }
}

}  // namespace view_selection::io
