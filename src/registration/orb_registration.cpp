#include "view_selection/registration/orb_registration.h"

#include "view_selection/images/image_conversion.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace view_selection::registration {

namespace {

constexpr int kMinOrbWidth = 320;

// keptBytes' little-endian fields (the registration stands on the core alone, not on io/).
void putU32(std::vector<uint8_t>& out, uint32_t v) {
  for (int b = 0; b < 4; ++b) out.push_back(static_cast<uint8_t>(v >> (8 * b)));
}

void putF32(std::vector<uint8_t>& out, float v) {
  uint32_t u;
  std::memcpy(&u, &v, 4);
  putU32(out, u);
}

/// Reads keptBytes' fields; `ok` turns false (and stays) at the first read past the end.
struct ByteReader {
  const std::vector<uint8_t>& bytes;
  size_t at = 0;
  bool ok = true;
  const uint8_t* take(size_t n) {
    if (!ok || n > bytes.size() - at) {
      ok = false;
      return nullptr;
    }
    const uint8_t* p = bytes.data() + at;
    at += n;
    return p;
  }
  uint32_t u32() {
    const uint8_t* p = take(4);
    uint32_t v = 0;
    if (p)
      for (int b = 0; b < 4; ++b) v |= static_cast<uint32_t>(p[b]) << (8 * b);
    return v;
  }
  float f32() {
    const uint32_t u = u32();
    float v;
    std::memcpy(&v, &u, 4);
    return v;
  }
  size_t left() const { return bytes.size() - at; }
};

cv::Mat greyOf(const core::ColourImage& image) {
  const cv::Mat m = images::matOf(image);
  if (m.channels() == 1) return m;
  cv::Mat grey;
  cv::cvtColor(m, grey, m.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  return grey;
}

}  // namespace

OrbRegistration::OrbRegistration(OrbRegistrationConfig config)
    : config_(config),
      orb_(cv::ORB::create(config.features, 1.2f, 8, 31, 0, 2, cv::ORB::HARRIS_SCORE, 31,
                           config.fast_threshold)) {}

const OrbRegistration::Features* OrbRegistration::frameFeatures(const core::Frame& frame) {
  if (!cached_stamp_ || *cached_stamp_ != frame.stamp) detect(frame);
  return cached_.keypoints.empty() ? nullptr : &cached_;
}

void OrbRegistration::detect(const core::Frame& frame) {
  cached_stamp_ = frame.stamp;
  cached_ = Features{};
  if (frame.image.empty()) return;
  const cv::Mat grey = greyOf(frame.image);
  // ORB's 31-pixel patches leave little of a small image: one narrower than kMinOrbWidth is
  // enlarged for the detection, and the keypoints are scaled back to its pixels.
  if (grey.cols < kMinOrbWidth) {
    const double scale = static_cast<double>(kMinOrbWidth) / grey.cols;
    cv::Mat larger;
    cv::resize(grey, larger, cv::Size(), scale, scale, cv::INTER_LINEAR);
    orb_->detectAndCompute(larger, cv::noArray(), cached_.keypoints, cached_.descriptors);
    for (cv::KeyPoint& k : cached_.keypoints) {
      // pixel centres: x_small = (x_large + 0.5) / scale - 0.5
      k.pt.x = static_cast<float>((k.pt.x + 0.5) / scale - 0.5);
      k.pt.y = static_cast<float>((k.pt.y + 0.5) / scale - 0.5);
    }
  } else {
    orb_->detectAndCompute(grey, cv::noArray(), cached_.keypoints, cached_.descriptors);
  }
  // The thumbnail: the image shrunk (area average), blurred, zero mean, unit norm.
  cv::Mat small;
  cv::resize(grey, small, cv::Size(kThumbnailWidth, kThumbnailHeight), 0, 0, cv::INTER_AREA);
  small.convertTo(small, CV_32F);
  cv::GaussianBlur(small, small, cv::Size(3, 3), 0.75);
  small = small.reshape(1, 1) - cv::mean(small)[0];
  const double norm = cv::norm(small);
  cached_.thumbnail = norm > 1e-6 ? cv::Mat(small / norm) : cv::Mat();
}

void OrbRegistration::makeRoom(core::ViewId id) {
  if (kept_.size() <= static_cast<size_t>(id)) kept_.resize(static_cast<size_t>(id) + 1);
  if (thumbnails_.rows <= id) {
    cv::Mat grown = cv::Mat::zeros(std::max(2 * thumbnails_.rows, id + 1),
                                   kThumbnailWidth * kThumbnailHeight, CV_32F);
    if (!thumbnails_.empty()) thumbnails_.copyTo(grown.rowRange(0, thumbnails_.rows));
    thumbnails_ = grown;
  }
  kept_[static_cast<size_t>(id)] = Kept{};
  thumbnails_.row(id).setTo(0.0f);
}

void OrbRegistration::keyframeAdded(core::ViewId id, const core::Frame& frame) {
  if (id < 0) return;
  makeRoom(id);
  Kept& k = kept_[static_cast<size_t>(id)];
  if (frame.depth.empty()) return;
  const Features* f = frameFeatures(frame);
  if (f == nullptr || f->thumbnail.empty()) return;
  const cv::Mat depth = images::matOf(frame.depth);
  const double sx = static_cast<double>(depth.cols) / frame.image.width;
  const double sy = static_cast<double>(depth.rows) / frame.image.height;
  for (size_t q = 0; q < f->keypoints.size(); ++q) {
    const cv::Point2f& p = f->keypoints[q].pt;
    const int u = static_cast<int>(p.x * sx), v = static_cast<int>(p.y * sy);
    if (u < 0 || v < 0 || u >= depth.cols || v >= depth.rows) continue;
    const float z = depth.at<float>(v, u);
    if (!(z > 0.0f) || !std::isfinite(z)) continue;
    const Eigen::Vector3d x =
        frame.intrinsics.backProject(Eigen::Vector2d(p.x, p.y)) * static_cast<double>(z);
    k.points.emplace_back(static_cast<float>(x.x()), static_cast<float>(x.y()),
                          static_cast<float>(x.z()));
    k.descriptors.push_back(f->descriptors.row(static_cast<int>(q)));
  }
  if (static_cast<int>(k.points.size()) < config_.min_inliers) {
    k = Kept{};
    return;
  }
  f->thumbnail.copyTo(thumbnails_.row(id));
}

std::vector<core::ViewId> OrbRegistration::alikeKeyframes(const core::Frame& frame,
                                                          core::ViewId below, std::size_t max) {
  std::vector<core::ViewId> out;
  const core::ViewId n = std::min<core::ViewId>(below, static_cast<core::ViewId>(kept_.size()));
  if (n <= 0 || max == 0) return out;
  const Features* f = frameFeatures(frame);
  if (f == nullptr || f->thumbnail.empty()) return out;
  const cv::Mat scores = thumbnails_.rowRange(0, n) * f->thumbnail.t();  // n x 1 correlations
  std::vector<std::pair<float, core::ViewId>> ranked;
  ranked.reserve(static_cast<size_t>(n));
  for (core::ViewId id = 0; id < n; ++id)
    if (!kept_[static_cast<size_t>(id)].points.empty())
      ranked.emplace_back(-scores.at<float>(id, 0), id);
  const size_t keep = std::min(max, ranked.size());
  std::partial_sort(ranked.begin(), ranked.begin() + static_cast<std::ptrdiff_t>(keep),
                    ranked.end());
  for (size_t q = 0; q < keep; ++q) out.push_back(ranked[q].second);
  return out;
}

std::optional<core::CameraPose> OrbRegistration::relativePose(const core::Frame& frame,
                                                              core::ViewId id) {
  if (id < 0 || static_cast<size_t>(id) >= kept_.size()) return std::nullopt;
  const Kept& k = kept_[static_cast<size_t>(id)];
  if (k.points.empty()) return std::nullopt;
  const Features* f = frameFeatures(frame);
  if (f == nullptr || f->descriptors.rows < 2) return std::nullopt;
  ++attempts_;

  std::vector<std::vector<cv::DMatch>> knn;
  cv::BFMatcher(cv::NORM_HAMMING).knnMatch(f->descriptors, k.descriptors, knn, 2);
  std::vector<cv::Point3f> object;
  std::vector<cv::Point2f> image;
  for (const auto& m : knn) {
    if (m.size() < 2 || m[0].distance >= config_.ratio * m[1].distance) continue;
    object.push_back(k.points[static_cast<size_t>(m[0].trainIdx)]);
    image.push_back(f->keypoints[static_cast<size_t>(m[0].queryIdx)].pt);
  }
  if (static_cast<int>(object.size()) < config_.min_inliers) return std::nullopt;

  const core::PinholeIntrinsics& in = frame.intrinsics;
  const cv::Matx33d camera(in.fx, 0.0, in.cx, 0.0, in.fy, in.cy, 0.0, 0.0, 1.0);
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  // RANSAC draws from OpenCV's global generator: seeded per call, so the same frame and keyframe
  // register the same way in the node and in select_views, whatever was drawn before.
  cv::theRNG().state = 0x5eed;
  if (!cv::solvePnPRansac(
          object, image, camera, cv::noArray(), rvec, tvec, false, config_.ransac_iterations,
          static_cast<float>(config_.max_reprojection_px), 0.999, inliers, cv::SOLVEPNP_EPNP))
    return std::nullopt;
  if (static_cast<int>(inliers.size()) < config_.min_inliers ||
      static_cast<double>(inliers.size()) < config_.min_inlier_share * object.size())
    return std::nullopt;
  std::vector<cv::Point3f> in_object;
  std::vector<cv::Point2f> in_image;
  for (const int q : inliers) {
    in_object.push_back(object[static_cast<size_t>(q)]);
    in_image.push_back(image[static_cast<size_t>(q)]);
  }
  cv::solvePnPRefineLM(in_object, in_image, camera, cv::noArray(), rvec, tvec);
  std::vector<cv::Point2f> projected;
  cv::projectPoints(in_object, rvec, tvec, camera, cv::noArray(), projected);
  double squared = 0.0;
  for (size_t q = 0; q < projected.size(); ++q) {
    const cv::Point2f d = projected[q] - in_image[q];
    squared += d.dot(d);
  }
  if (!(std::sqrt(squared / projected.size()) < 0.5 * config_.max_reprojection_px))
    return std::nullopt;

  // PnP gives keyframe camera -> frame camera: x_f = R x_k + t. The frame's camera in the
  // keyframe's frame is the inverse.
  cv::Mat r;
  cv::Rodrigues(rvec, r);
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  cv::cv2eigen(r, rotation);
  cv::cv2eigen(tvec, translation);
  core::CameraPose pose;
  pose.orientation = Eigen::Quaterniond(rotation.transpose()).normalized();
  pose.position = -rotation.transpose() * translation;
  if (!pose.isValid()) return std::nullopt;
  ++registrations_;
  return pose;
}

// keptBytes: u32 features n, u32 descriptor bytes d (ORB's 32), n x d descriptor bytes, n x 3
// f32 points (the keyframe's camera frame), kThumbnailWidth x kThumbnailHeight f32 thumbnail;
// little-endian.
std::vector<uint8_t> OrbRegistration::keptBytes(core::ViewId id) const {
  std::vector<uint8_t> out;
  if (id < 0 || static_cast<size_t>(id) >= kept_.size()) return out;
  const Kept& k = kept_[static_cast<size_t>(id)];
  if (k.points.empty()) return out;
  const auto d = static_cast<size_t>(k.descriptors.cols);
  out.reserve(8 + k.points.size() * (d + 12) + 4 * kThumbnailWidth * kThumbnailHeight);
  putU32(out, static_cast<uint32_t>(k.points.size()));
  putU32(out, static_cast<uint32_t>(d));
  for (int r = 0; r < k.descriptors.rows; ++r)
    out.insert(out.end(), k.descriptors.ptr<uint8_t>(r), k.descriptors.ptr<uint8_t>(r) + d);
  for (const cv::Point3f& p : k.points) {
    putF32(out, p.x);
    putF32(out, p.y);
    putF32(out, p.z);
  }
  const float* t = thumbnails_.ptr<float>(id);
  for (int q = 0; q < kThumbnailWidth * kThumbnailHeight; ++q) putF32(out, t[q]);
  return out;
}

bool OrbRegistration::restoreKept(core::ViewId id, const std::vector<uint8_t>& bytes) {
  if (id < 0) return false;
  ByteReader r{bytes};
  const uint32_t n = r.u32(), d = r.u32();
  const size_t thumbnail_bytes = 4 * static_cast<size_t>(kThumbnailWidth * kThumbnailHeight);
  if (!r.ok || d != static_cast<uint32_t>(orb_->descriptorSize()) || n < 1 ||
      r.left() != static_cast<size_t>(n) * (d + 12) + thumbnail_bytes)
    return false;
  Kept k;
  k.descriptors.create(static_cast<int>(n), static_cast<int>(d), CV_8U);
  for (int q = 0; q < static_cast<int>(n); ++q)
    std::memcpy(k.descriptors.ptr<uint8_t>(q), r.take(d), d);
  k.points.reserve(n);
  for (uint32_t q = 0; q < n; ++q) {
    const float x = r.f32(), y = r.f32(), z = r.f32();
    if (!std::isfinite(x) || !std::isfinite(y) || !(z > 0.0f) || !std::isfinite(z)) return false;
    k.points.emplace_back(x, y, z);
  }
  cv::Mat thumbnail(1, kThumbnailWidth * kThumbnailHeight, CV_32F);
  for (int q = 0; q < thumbnail.cols; ++q) {
    thumbnail.at<float>(0, q) = r.f32();
    if (!std::isfinite(thumbnail.at<float>(0, q))) return false;
  }
  makeRoom(id);
  kept_[static_cast<size_t>(id)] = std::move(k);
  thumbnail.copyTo(thumbnails_.row(id));
  return true;
}

void OrbRegistration::clear() {
  kept_.clear();
  thumbnails_.release();
  cached_stamp_.reset();
  cached_ = Features{};
}

std::size_t OrbRegistration::keyframesKept() const {
  std::size_t n = 0;
  for (const Kept& k : kept_) n += k.points.empty() ? 0 : 1;
  return n;
}

std::size_t OrbRegistration::bytes() const {
  std::size_t n = 0;
  for (const Kept& k : kept_)
    n += k.descriptors.total() * k.descriptors.elemSize() + k.points.size() * sizeof(cv::Point3f);
  return n + thumbnails_.total() * thumbnails_.elemSize();
}

}  // namespace view_selection::registration
