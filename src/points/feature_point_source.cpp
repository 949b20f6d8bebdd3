#include "view_selection/points/feature_point_source.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/images/image_conversion.h"

#include <opencv2/core/hal/hal.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <ctime>
#include <set>
#include <sstream>

namespace view_selection::points {

namespace {

// Stage times are CPU time of the whole process (every thread OpenCV may use): the work one
// core does, which a busy, shared machine does not inflate the way it inflates wall time.
double cpuNow() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}
double secondsSince(double start) { return cpuNow() - start; }

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid), values.end());
  return values[mid];
}

// Hamming distance of two ORB descriptors (32 bytes): on x86, the hardware popcount when the
// processor has one (checked at run time; the package is built for the baseline instruction
// set, where OpenCV's table-driven version measured several times slower); elsewhere OpenCV's.
#if defined(__x86_64__) || defined(__i386__)
__attribute__((target("popcnt"))) int hammingPopcnt(const uchar* a, const uchar* b, int bytes) {
  int d = 0;
  int i = 0;
  for (; i + 8 <= bytes; i += 8) {
    uint64_t x, y;
    std::memcpy(&x, a + i, 8);
    std::memcpy(&y, b + i, 8);
    d += __builtin_popcountll(x ^ y);
  }
  for (; i < bytes; ++i) d += __builtin_popcount(static_cast<unsigned>(a[i] ^ b[i]));
  return d;
}

int hamming(const uchar* a, const uchar* b, int bytes) {
  static const bool has_popcnt = __builtin_cpu_supports("popcnt");
  return has_popcnt ? hammingPopcnt(a, b, bytes) : cv::hal::normHamming(a, b, bytes);
}
#else
int hamming(const uchar* a, const uchar* b, int bytes) { return cv::hal::normHamming(a, b, bytes); }
#endif

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return s;
}

cv::Mat toGrey(const cv::Mat& image) {
  if (image.empty())
    throw core::InvalidInput("point source 'features' needs the image, but the frame has none");
  if (image.depth() != CV_8U)
    throw core::InvalidInput("point source 'features' needs an 8-bit image (grey, BGR or BGRA)");
  cv::Mat grey;
  switch (image.channels()) {
    case 1:
      return image;
    case 3:
      cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
      return grey;
    case 4:
      cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
      return grey;
    default:
      throw core::InvalidInput("point source 'features' needs a grey, BGR or BGRA image, got " +
                               std::to_string(image.channels()) + " channels");
  }
}

}  // namespace

void FeaturePointSourceConfig::visitParameters(core::ParameterVisitor& v) {
  v.section("Points from features (no depth)");
  core::visitText(v, "features", detector, {"orb", "sift"}, "features: detector, orb or sift");
  core::visitInteger(v, "max_features", max_features, 1, 1000000, "features: per keyframe");
  core::visitInteger(v, "feature_max_match_views", max_match_views, 1, 1000,
                     "features: earlier keyframes matched against each new one");
  core::visitReal(v, "feature_min_overlap", min_overlap, 0.0, 1.0,
                  "features: estimated frustum overlap for a candidate keyframe");
  core::visitReal(v, "feature_ratio", ratio, 1e-6, 1.0,
                  "features: Lowe's ratio test, best < ratio * second best");
  core::visitReal(v, "feature_max_sampson_px", max_sampson_px, 1e-6, 1e6,
                  "features: epipolar check from the known poses [px]");
  core::visitReal(v, "feature_max_reprojection_px", max_reprojection_px, 1e-6, 1e6,
                  "features: after refinement, per observation [px]");
  core::visitReal(v, "feature_min_parallax_deg", min_parallax_deg, 0.0, 89.9,
                  "features: largest angle between a point's observing rays [deg]");
  core::visitReal(v, "feature_huber_px", huber_px, 1e-6, 1e6,
                  "features: robust loss scale of the refinement [px]");
  core::visitInteger(v, "feature_max_refine_iterations", max_refine_iterations, 1, 10000,
                     "features: Levenberg-Marquardt iterations per point");
  core::visitInteger(v, "feature_keep_descriptor_views", keep_descriptor_views, 1, 10000000,
                     "features: keyframes that keep their descriptors to be matched (the most "
                     "recently used); older ones keep only their tracked features and points");
}

FeaturePointSource::FeaturePointSource(FeaturePointSourceConfig config)
    : config_(std::move(config)) {
  config_.validate();
  if (config_.detector == "orb") {
    detector_ = cv::ORB::create(config_.max_features);
    norm_ = cv::NORM_HAMMING;
  } else {
    detector_ = cv::SIFT::create(config_.max_features);
    norm_ = cv::NORM_L2;
  }
}

void FeaturePointSource::reset() {
  views_.clear();
  cameras_.clear();
  index_of_.clear();
  tracks_.clear();
  last_candidates_.clear();
  grid_.clear();
  clock_ = 0;
  last_use_.clear();
  in_use_.clear();
  last_ = total_ = FeatureStats{};
}

double FeaturePointSource::frustumOverlap(const TriangulationCamera& a,
                                          const TriangulationCamera& b,
                                          const std::vector<double>& depths) {
  constexpr int kCols = 8, kRows = 6;
  int seen = 0, total = 0;
  for (int direction = 0; direction < 2; ++direction) {
    const TriangulationCamera& from = direction == 0 ? a : b;
    const TriangulationCamera& to = direction == 0 ? b : a;
    const Eigen::Matrix3d camera_to_world = from.world_to_camera.transpose();
    for (int r = 0; r < kRows; ++r) {
      for (int c = 0; c < kCols; ++c) {
        const Eigen::Vector2d px((c + 0.5) * from.intrinsics.width / kCols,
                                 (r + 0.5) * from.intrinsics.height / kRows);
        const Eigen::Vector3d ray = camera_to_world * from.intrinsics.backProject(px);
        for (const double d : depths) {
          const Eigen::Vector3d p = to.toCamera(from.centre + d * ray);
          ++total;
          if (p.z() > 0.0 && to.intrinsics.inImage(to.intrinsics.project(p))) ++seen;
        }
      }
    }
  }
  return total > 0 ? static_cast<double>(seen) / total : 0.0;
}

Eigen::Matrix3d FeaturePointSource::fundamental(const TriangulationCamera& from,
                                                const TriangulationCamera& to) {
  const Eigen::Matrix3d r = to.world_to_camera * from.world_to_camera.transpose();
  const Eigen::Vector3d t = to.world_to_camera * (from.centre - to.centre);
  const Eigen::Matrix3d e = skew(t) * r;
  return to.intrinsics.matrix().inverse().transpose() * e * from.intrinsics.matrix().inverse();
}

double FeaturePointSource::sampsonDistance(const Eigen::Matrix3d& f, const Eigen::Vector2d& from,
                                           const Eigen::Vector2d& to) {
  const Eigen::Vector3d x1 = from.homogeneous(), x2 = to.homogeneous();
  const Eigen::Vector3d fx1 = f * x1, ftx2 = f.transpose() * x2;
  const double e = x2.dot(fx1);
  const double denom =
      fx1.x() * fx1.x() + fx1.y() * fx1.y() + ftx2.x() * ftx2.x() + ftx2.y() * ftx2.y();
  if (!(denom > 0.0)) return std::numeric_limits<double>::infinity();
  return std::sqrt(e * e / denom);
}

std::vector<int> FeaturePointSource::chooseCandidates(const TriangulationCamera& camera,
                                                       size_t* scored_views) {
  // The scene's depth from the recent keyframes: their median depths, the median and the largest.
  std::vector<double> medians;
  for (size_t v = views_.size(); v-- > 0 && medians.size() < static_cast<size_t>(kDepthViews);)
    if (views_[v].median_depth > 0.0) medians.push_back(views_[v].median_depth);
  const double scene_depth = median(medians);
  const double far_depth = medians.empty() ? 0.0 : *std::max_element(medians.begin(), medians.end());
  std::vector<core::ViewId> near;
  if (far_depth > 0.0) {
    grid_.query(camera.centre, kCandidateDepths * far_depth, near);
  } else {  // nothing triangulated yet: the most recent keyframes
    const size_t recent = static_cast<size_t>(kRecentFactor * config_.max_match_views);
    for (size_t v = views_.size() > recent ? views_.size() - recent : 0; v < views_.size(); ++v)
      near.push_back(static_cast<core::ViewId>(v));
  }
  std::vector<std::pair<double, int>> scored;
  size_t estimated = 0;
  for (const core::ViewId id : near) {
    const size_t v = static_cast<size_t>(id);
    if (views_[v].descriptors.empty()) continue;  // released: cannot be matched
    const TriangulationCamera& other = cameras_[v];
    const double baseline = (other.centre - camera.centre).norm();
    if (!(baseline > 0.0)) continue;  // no triangulation from one centre
    // Depths at which the overlap is estimated: this view's own points, else the scene's,
    // else (nothing triangulated yet) a range of multiples of the baseline.
    std::vector<double> depths;
    const double d = views_[v].median_depth > 0.0 ? views_[v].median_depth : scene_depth;
    if (d > 0.0)
      depths = {0.6 * d, d, 1.6 * d};
    else
      depths = {2.0 * baseline, 5.0 * baseline, 20.0 * baseline};
    ++estimated;
    const double overlap = frustumOverlap(other, camera, depths);
    if (overlap >= config_.min_overlap && overlap > 0.0)
      scored.emplace_back(overlap, static_cast<int>(v));
  }
  if (scored_views) *scored_views = estimated;
  // Best overlap first; among equals the most recent view.
  std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second > b.second;
  });
  std::vector<int> chosen;
  for (const auto& [overlap, v] : scored) {
    if (static_cast<int>(chosen.size()) >= config_.max_match_views) break;
    chosen.push_back(v);
  }
  return chosen;
}

void FeaturePointSource::use(int view) {
  const size_t v = static_cast<size_t>(view);
  if (last_use_.size() <= v) last_use_.resize(v + 1, 0);
  in_use_.erase({last_use_[v], view});
  last_use_[v] = ++clock_;
  if (!views_[v].descriptors.empty()) in_use_.insert({last_use_[v], view});
}

void FeaturePointSource::releaseOld() {
  while (in_use_.size() > static_cast<size_t>(config_.keep_descriptor_views)) {
    const int view = in_use_.begin()->second;
    in_use_.erase(in_use_.begin());
    release(view);
  }
}

void FeaturePointSource::release(int view) {
  View& v = views_[static_cast<size_t>(view)];
  v.descriptors.release();
  v.index = StripIndex{};
  // Features that can never be used again are dropped, the others renumbered in the view and
  // in their tracks: those in no track (nothing can match them now), and those of a track
  // without a point whose every other view is released too (no match can reach it again, so
  // it will never be triangulated).
  std::vector<cv::KeyPoint> kept;
  std::vector<int> kept_tracks;
  for (size_t f = 0; f < v.keypoints.size(); ++f) {
    const int t = v.track_of[f];
    if (t < 0) continue;
    Track& track = tracks_[static_cast<size_t>(t)];
    bool reachable = track.valid;
    for (const auto& [ov, of] : track.obs)
      reachable = reachable || (ov != view && !views_[static_cast<size_t>(ov)].descriptors.empty());
    if (!reachable) {
      track.obs.erase(std::remove(track.obs.begin(), track.obs.end(),
                                  std::make_pair(view, static_cast<int>(f))),
                      track.obs.end());
      if (track.obs.empty()) std::vector<std::pair<int, int>>().swap(track.obs);
      continue;
    }
    for (auto& [ov, of] : track.obs)
      if (ov == view && of == static_cast<int>(f)) of = static_cast<int>(kept.size());
    kept.push_back(v.keypoints[f]);
    kept_tracks.push_back(t);
  }
  v.keypoints = std::move(kept);
  v.keypoints.shrink_to_fit();
  v.track_of = std::move(kept_tracks);
}

FeaturePointSource::MemoryUse FeaturePointSource::memoryUse() const {
  MemoryUse m;
  for (const View& v : views_) {
    m.features += sizeof(View) + v.keypoints.capacity() * sizeof(cv::KeyPoint) +
                  v.track_of.capacity() * sizeof(int);
    if (!v.descriptors.empty()) m.descriptors += v.descriptors.total() * v.descriptors.elemSize();
    for (const auto& strip : v.index.by_x) m.descriptors += strip.capacity() * sizeof(strip[0]);
    for (const auto& strip : v.index.by_y) m.descriptors += strip.capacity() * sizeof(strip[0]);
    m.points += static_cast<size_t>(v.emitted.size()) * sizeof(double);
  }
  for (const Track& t : tracks_) m.tracks += sizeof(Track) + t.obs.capacity() * sizeof(t.obs[0]);
  m.features += cameras_.capacity() * sizeof(TriangulationCamera);
  return m;
}

void FeaturePointSource::StripIndex::build(const std::vector<cv::KeyPoint>& keypoints, int width,
                                           int height) {
  by_x.assign(static_cast<size_t>(width / kStrip + 1), {});
  by_y.assign(static_cast<size_t>(height / kStrip + 1), {});
  for (size_t k = 0; k < keypoints.size(); ++k) {
    const cv::Point2f& p = keypoints[k].pt;
    const int sx = std::clamp(static_cast<int>(p.x) / kStrip, 0, static_cast<int>(by_x.size()) - 1);
    const int sy = std::clamp(static_cast<int>(p.y) / kStrip, 0, static_cast<int>(by_y.size()) - 1);
    by_x[static_cast<size_t>(sx)].emplace_back(p.y, static_cast<int>(k));
    by_y[static_cast<size_t>(sy)].emplace_back(p.x, static_cast<int>(k));
  }
  for (auto& strip : by_x) std::sort(strip.begin(), strip.end());
  for (auto& strip : by_y) std::sort(strip.begin(), strip.end());
}

void FeaturePointSource::StripIndex::near(const Eigen::Vector3d& line, double band,
                                          const std::vector<cv::KeyPoint>& keypoints,
                                          std::vector<int>& out) const {
  const double a = line.x(), b = line.y(), c = line.z();
  const double norm = std::hypot(a, b);
  if (!(norm > 0.0)) return;
  // Along the axis the line changes slower in: strips across x when |b| >= |a| (y = f(x)).
  const bool across_x = std::abs(b) >= std::abs(a);
  const auto& strips = across_x ? by_x : by_y;
  const double p = across_x ? a : b, q = across_x ? b : a;  // p * s + q * t + c = 0, t = f(s)
  const double widen = band * norm / std::abs(q);           // band measured along t
  for (size_t k = 0; k < strips.size(); ++k) {
    if (strips[k].empty()) continue;
    const double s0 = static_cast<double>(k) * kStrip, s1 = s0 + kStrip;
    const double t0 = -(p * s0 + c) / q, t1 = -(p * s1 + c) / q;
    const float lo = static_cast<float>(std::min(t0, t1) - widen);
    const float hi = static_cast<float>(std::max(t0, t1) + widen);
    auto it = std::lower_bound(strips[k].begin(), strips[k].end(), std::make_pair(lo, -1));
    for (; it != strips[k].end() && it->first <= hi; ++it) {
      const cv::Point2f& pt = keypoints[static_cast<size_t>(it->second)].pt;
      if (std::abs(a * pt.x + b * pt.y + c) <= band * norm) out.push_back(it->second);
    }
  }
}

std::vector<cv::DMatch> FeaturePointSource::match(const View& next, int candidate) const {
  const View& other = views_[static_cast<size_t>(candidate)];
  if (next.descriptors.empty() || other.descriptors.rows < 2) return {};
  // x_next^T F x_other = 0: the line of a new feature in the other image is F^T x_next.
  const Eigen::Matrix3d f = fundamental(cameras_[static_cast<size_t>(candidate)], cameras_.back());
  const double band = kBandFactor * config_.max_sampson_px;
  const bool binary = norm_ == cv::NORM_HAMMING;
  const int length = next.descriptors.cols;
  std::vector<int> near;
  // At most one match per feature of the other view: the closest.
  std::vector<int> best_for(static_cast<size_t>(other.descriptors.rows), -1);
  std::vector<cv::DMatch> kept;
  for (int a = 0; a < next.descriptors.rows; ++a) {
    const cv::Point2f& pa = next.keypoints[static_cast<size_t>(a)].pt;
    const Eigen::Vector2d xa(pa.x, pa.y);
    near.clear();
    other.index.near(f.transpose() * xa.homogeneous(), band, other.keypoints, near);
    if (near.size() < 2) continue;  // no competitor: the ratio test cannot vouch for it
    float best = std::numeric_limits<float>::infinity(), second = best;
    int best_k = -1;
    for (const int k : near) {
      const float d = binary
                          ? static_cast<float>(hamming(next.descriptors.ptr<uchar>(a),
                                                       other.descriptors.ptr<uchar>(k), length))
                          : std::sqrt(cv::hal::normL2Sqr_(next.descriptors.ptr<float>(a),
                                                          other.descriptors.ptr<float>(k), length));
      if (d < best) {
        second = best;
        best = d;
        best_k = k;
      } else if (d < second) {
        second = d;
      }
    }
    if (!(best < static_cast<float>(config_.ratio) * second)) continue;
    const cv::Point2f& pb = other.keypoints[static_cast<size_t>(best_k)].pt;
    if (sampsonDistance(f, Eigen::Vector2d(pb.x, pb.y), xa) > config_.max_sampson_px) continue;
    const cv::DMatch m(a, best_k, best);
    int& slot = best_for[static_cast<size_t>(best_k)];
    if (slot < 0) {
      slot = static_cast<int>(kept.size());
      kept.push_back(m);
    } else if (m.distance < kept[static_cast<size_t>(slot)].distance) {
      kept[static_cast<size_t>(slot)] = m;
    }
  }
  return kept;
}

bool FeaturePointSource::trackHasView(int track, int view) const {
  for (const auto& [v, f] : tracks_[static_cast<size_t>(track)].obs)
    if (v == view) return true;
  return false;
}

void FeaturePointSource::triangulateTracks(const std::vector<int>& tracks) {
  auto observationsOf = [this](const Track& t) {
    std::vector<PixelObservation> obs;
    for (const auto& [v, f] : t.obs) {
      const cv::Point2f& p = views_[static_cast<size_t>(v)].keypoints[static_cast<size_t>(f)].pt;
      obs.push_back({v, Eigen::Vector2d(p.x, p.y)});
    }
    return obs;
  };
  auto inFront = [this](const Eigen::Vector3d& x, const std::vector<PixelObservation>& obs) {
    for (const auto& o : obs)
      if (!(cameras_[static_cast<size_t>(o.camera)].toCamera(x).z() > 0.0)) return false;
    return true;
  };
  const RefineOptions refine{config_.huber_px, config_.max_refine_iterations};

  std::vector<int> batch = tracks;
  for (int round = 0; round < 2 && !batch.empty(); ++round) {
    // Linear start; tracks behind a camera already are rejected before refinement.
    std::vector<int> ids;
    std::vector<Eigen::Vector3d> points;
    std::vector<std::vector<PixelObservation>> observations;
    for (const int t : batch) {
      Track& track = tracks_[static_cast<size_t>(t)];
      track.valid = false;
      if (track.obs.size() < 2) continue;
      auto obs = observationsOf(track);
      const Eigen::Vector3d x = triangulateLinear(obs, cameras_);
      if (!x.allFinite() || !inFront(x, obs)) continue;
      ids.push_back(t);
      points.push_back(x);
      observations.push_back(std::move(obs));
    }
    const auto t_refine = cpuNow();
    refinePoints(points, observations, cameras_, refine);
    refine_seconds_ += secondsSince(t_refine);

    std::vector<int> again;
    for (size_t q = 0; q < ids.size(); ++q) {
      Track& track = tracks_[static_cast<size_t>(ids[q])];
      const Eigen::Vector3d& x = points[q];
      const auto& obs = observations[q];
      if (!x.allFinite() || !inFront(x, obs)) continue;  // cheirality
      std::vector<double> errors;
      for (const auto& o : obs) errors.push_back(reprojectionError(x, o, cameras_));
      const double worst = *std::max_element(errors.begin(), errors.end());
      if (worst > config_.max_reprojection_px) {
        // A track of three or more may hold one wrong match: drop the observations that do not
        // fit and triangulate the rest once more. A pair that does not fit stays without point.
        if (round == 0 && obs.size() > 2) {
          std::vector<std::pair<int, int>> kept;
          for (size_t k = 0; k < obs.size(); ++k) {
            if (errors[k] <= config_.max_reprojection_px) {
              kept.push_back(track.obs[k]);
            } else {
              views_[static_cast<size_t>(track.obs[k].first)]
                  .track_of[static_cast<size_t>(track.obs[k].second)] = -1;
            }
          }
          track.obs = std::move(kept);
          if (track.obs.size() >= 2) again.push_back(ids[q]);
        }
        continue;
      }
      if (maxParallaxDeg(x, obs, cameras_) < config_.min_parallax_deg) continue;
      track.point = x;
      track.valid = true;
    }
    batch = std::move(again);
  }
}

Eigen::Matrix3Xd FeaturePointSource::pointsOfIndex(int view) const {
  const View& v = views_[static_cast<size_t>(view)];
  std::vector<int> valid;
  for (const int t : v.track_of)
    if (t >= 0 && tracks_[static_cast<size_t>(t)].valid) valid.push_back(t);
  Eigen::Matrix3Xd points(3, static_cast<Eigen::Index>(valid.size()));
  for (size_t q = 0; q < valid.size(); ++q)
    points.col(static_cast<Eigen::Index>(q)) = tracks_[static_cast<size_t>(valid[q])].point;
  return points;
}

void FeaturePointSource::updateMedianDepth(int view) {
  View& v = views_[static_cast<size_t>(view)];
  std::vector<double> depths;
  for (Eigen::Index c = 0; c < v.emitted.cols(); ++c)
    depths.push_back(cameras_[static_cast<size_t>(view)].toCamera(v.emitted.col(c)).z());
  v.median_depth = median(depths);
}

Eigen::Matrix3Xd FeaturePointSource::pointsOf(core::ViewId id) const {
  const auto it = index_of_.find(id);
  return it == index_of_.end() ? Eigen::Matrix3Xd(3, 0) : pointsOfIndex(it->second);
}

FeatureStats& FeatureStats::operator+=(const FeatureStats& o) {
  extract_seconds += o.extract_seconds;
  match_seconds += o.match_seconds;
  triangulate_seconds += o.triangulate_seconds;
  refine_seconds += o.refine_seconds;
  features += o.features;
  candidates += o.candidates;
  scored += o.scored;
  matches += o.matches;
  points += o.points;
  keyframes += o.keyframes;
  return *this;
}

FeaturePointSource::State FeaturePointSource::state() const {
  State s;
  s.views.reserve(views_.size());
  for (const View& v : views_) s.views.push_back(v);  // the ViewState part
  s.tracks = tracks_;
  return s;
}

void FeaturePointSource::restore(State state) {
  auto bad = [](const std::string& what) {
    throw core::InvalidInput("feature point source: saved state is inconsistent: " + what);
  };
  const int type = norm_ == cv::NORM_HAMMING ? CV_8U : CV_32F;
  const int length = norm_ == cv::NORM_HAMMING ? 32 : 128;
  const size_t n = state.views.size();
  for (size_t i = 0; i < n; ++i) {
    const ViewState& v = state.views[i];
    const std::string which = "keyframe " + std::to_string(v.id);
    if (v.id < 0 || (i > 0 && v.id <= state.views[i - 1].id)) bad("ids do not ascend");
    if (!v.intrinsics.isValid() || !v.pose.isValid()) bad(which + " intrinsics or pose");
    if (v.track_of.size() != v.keypoints.size()) bad(which + " track list size");
    if (!v.keypoints.empty() && !v.descriptors.empty() &&
        (v.descriptors.rows != static_cast<int>(v.keypoints.size()) ||
         v.descriptors.cols != length || v.descriptors.type() != type))
      bad(which + " descriptors do not fit the keypoints or the detector '" + config_.detector +
          "'");
    for (const cv::KeyPoint& k : v.keypoints)
      if (!std::isfinite(k.pt.x) || !std::isfinite(k.pt.y)) bad(which + " keypoint not finite");
    if (!std::isfinite(v.median_depth) || !v.emitted.allFinite()) bad(which + " points");
    for (const int t : v.track_of)
      if (t < -1 || t >= static_cast<int>(state.tracks.size())) bad(which + " track index");
  }
  for (size_t t = 0; t < state.tracks.size(); ++t) {
    const Track& track = state.tracks[t];
    if (!track.point.allFinite()) bad("track " + std::to_string(t) + " point");
    for (const auto& [v, f] : track.obs) {
      if (v < 0 || static_cast<size_t>(v) >= n || f < 0 ||
          static_cast<size_t>(f) >= state.views[static_cast<size_t>(v)].keypoints.size())
        bad("track " + std::to_string(t) + " observation out of range");
      if (state.views[static_cast<size_t>(v)].track_of[static_cast<size_t>(f)] !=
          static_cast<int>(t))
        bad("track " + std::to_string(t) + " and its feature disagree");
    }
  }
  std::vector<View> views(n);
  std::vector<TriangulationCamera> cameras;
  std::map<core::ViewId, int> index_of;
  for (size_t i = 0; i < n; ++i) {
    static_cast<ViewState&>(views[i]) = std::move(state.views[i]);
    View& v = views[i];
    if (!v.descriptors.empty()) v.index.build(v.keypoints, v.intrinsics.width, v.intrinsics.height);
    cameras.push_back(TriangulationCamera::from(v.intrinsics, v.pose));
    index_of[v.id] = static_cast<int>(i);
  }
  views_ = std::move(views);
  cameras_ = std::move(cameras);
  index_of_ = std::move(index_of);
  tracks_ = std::move(state.tracks);
  last_candidates_.clear();
  grid_.clear();
  clock_ = 0;
  last_use_.clear();
  in_use_.clear();
  for (size_t i = 0; i < views_.size(); ++i) {  // in arrival order: the newest used last
    grid_.insert(static_cast<core::ViewId>(i), cameras_[i].centre);
    use(static_cast<int>(i));
  }
  releaseOld();
  last_ = total_ = FeatureStats{};
}

size_t FeaturePointSource::validTracks() const {
  size_t n = 0;
  for (const Track& t : tracks_) n += (t.alive && t.valid) ? 1 : 0;
  return n;
}

core::PointSourceResult FeaturePointSource::process(core::ViewId id, const core::Frame& frame) {
  // Everything that can throw comes before the first change of state.
  const cv::Mat grey = toGrey(images::matOf(frame.image));
  if (!index_of_.empty() && id <= index_of_.rbegin()->first) {
    std::ostringstream s;
    s << "feature point source: keyframe id " << id << " is not after the previous one ("
      << index_of_.rbegin()->first << "); call reset() to start over";
    throw core::InvalidArgument(s.str());
  }
  if (!frame.intrinsics.isValid() || !frame.pose.isValid())
    throw core::InvalidInput("feature point source: the frame's intrinsics or pose are unusable");
  if (grey.cols != frame.intrinsics.width || grey.rows != frame.intrinsics.height)
    throw core::InvalidInput("feature point source: image size differs from the intrinsics' size");

  FeatureStats stats;
  auto t0 = cpuNow();
  View next;
  next.id = id;
  next.intrinsics = frame.intrinsics;
  next.pose = frame.pose;
  detector_->detectAndCompute(grey, cv::noArray(), next.keypoints, next.descriptors);
  next.track_of.assign(next.keypoints.size(), -1);
  next.index.build(next.keypoints, frame.intrinsics.width, frame.intrinsics.height);
  stats.extract_seconds = secondsSince(t0);
  stats.features = next.keypoints.size();

  t0 = cpuNow();
  const TriangulationCamera camera = TriangulationCamera::from(frame.intrinsics, frame.pose);
  const std::vector<int> candidates = chooseCandidates(camera, &stats.scored);
  const int n = static_cast<int>(views_.size());
  views_.push_back(std::move(next));
  cameras_.push_back(camera);
  index_of_[id] = n;
  grid_.insert(n, camera.centre);
  use(n);
  for (const int c : candidates) use(c);
  std::vector<std::vector<cv::DMatch>> matches;
  for (const int c : candidates) {
    matches.push_back(match(views_[static_cast<size_t>(n)], c));
    stats.matches += matches.back().size();
  }
  stats.candidates = candidates.size();
  last_candidates_.clear();
  for (const int c : candidates) last_candidates_.push_back(views_[static_cast<size_t>(c)].id);
  stats.match_seconds = secondsSince(t0);

  t0 = cpuNow();
  const std::set<int> touched = joinTracks(n, candidates, matches);
  std::vector<int> live;
  std::set<int> affected;
  for (const int t : touched) {
    if (!tracks_[static_cast<size_t>(t)].alive) continue;
    live.push_back(t);
    for (const auto& [v, f] : tracks_[static_cast<size_t>(t)].obs) affected.insert(v);
  }
  refine_seconds_ = 0.0;
  triangulateTracks(live);
  stats.refine_seconds = refine_seconds_;

  core::PointSourceResult result;
  for (const int v : affected) {
    if (v == n) continue;
    Eigen::Matrix3Xd points = pointsOfIndex(v);
    View& view = views_[static_cast<size_t>(v)];
    if (points.cols() == view.emitted.cols() && points == view.emitted) continue;  // unchanged
    view.emitted = points;
    updateMedianDepth(v);
    result.updated.emplace_back(view.id, std::move(points));
  }
  result.points = pointsOfIndex(n);
  views_[static_cast<size_t>(n)].emitted = result.points;
  updateMedianDepth(n);
  stats.triangulate_seconds = secondsSince(t0);
  stats.points = static_cast<size_t>(result.points.cols());
  stats.keyframes = 1;

  releaseOld();

  last_ = stats;
  total_ += stats;
  return result;
}

std::set<int> FeaturePointSource::joinTracks(int n, const std::vector<int>& candidates,
                                             const std::vector<std::vector<cv::DMatch>>& matches) {
  // Tracks: the union of the matches, never two features of one view in a track.
  std::set<int> touched;
  for (size_t q = 0; q < candidates.size(); ++q) {
    const int c = candidates[q];
    for (const cv::DMatch& m : matches[q]) {
      int& ta = views_[static_cast<size_t>(n)].track_of[static_cast<size_t>(m.queryIdx)];
      int& tb = views_[static_cast<size_t>(c)].track_of[static_cast<size_t>(m.trainIdx)];
      if (ta < 0 && tb < 0) {
        Track t;
        t.obs = {{c, m.trainIdx}, {n, m.queryIdx}};
        ta = tb = static_cast<int>(tracks_.size());
        tracks_.push_back(std::move(t));
        touched.insert(ta);
      } else if (ta < 0) {
        if (trackHasView(tb, n)) continue;  // another feature of the new view is in it
        tracks_[static_cast<size_t>(tb)].obs.emplace_back(n, m.queryIdx);
        ta = tb;
        touched.insert(tb);
      } else if (tb < 0) {
        if (trackHasView(ta, c)) continue;
        tracks_[static_cast<size_t>(ta)].obs.emplace_back(c, m.trainIdx);
        tb = ta;
        touched.insert(ta);
      } else if (ta != tb) {
        // Merge the smaller track into the larger unless they share a view.
        int keep = ta, drop = tb;
        if (tracks_[static_cast<size_t>(keep)].obs.size() <
            tracks_[static_cast<size_t>(drop)].obs.size())
          std::swap(keep, drop);
        bool conflict = false;
        for (const auto& [v, f] : tracks_[static_cast<size_t>(drop)].obs)
          conflict = conflict || trackHasView(keep, v);
        if (conflict) continue;
        Track& dropped = tracks_[static_cast<size_t>(drop)];
        for (const auto& [v, f] : dropped.obs) {
          views_[static_cast<size_t>(v)].track_of[static_cast<size_t>(f)] = keep;
          tracks_[static_cast<size_t>(keep)].obs.emplace_back(v, f);
        }
        dropped.obs.clear();
        dropped.alive = false;
        dropped.valid = false;
        touched.insert(keep);
      }
    }
  }
  return touched;
}

}  // namespace view_selection::points
