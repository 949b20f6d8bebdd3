#include "view_selection/core/error_resistance_matrix.h"

#include "view_selection/core/error_resistance.h"
#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <string>

namespace view_selection::core {

void ErrorResistanceConfig::visitParameters(ParameterVisitor& v) {
  v.section("The error-resistance matrix: gates");
  visitChoice(v, "gate", gate, kGateNames,
              "which points count for E[i][j]: paper (every visible point; sets the four values "
              "below and max_view_angle_deg to the paper's) or matchable (visible, parallax and "
              "footprint ratio within the limits below)");
  visitReal(v, "max_parallax_deg", max_parallax_deg, 0.0, 180.0,
            "matchable: a point counts where the angle at it between the two rays is at most "
            "this [deg]; 0 = off");
  visitReal(v, "max_scale_ratio", max_scale_ratio, 0.0, 1e6,
            "matchable: ... and the pixel-footprint ratio of the two views at it is at most "
            "this; 0 = off, else >= 1");
  visitInteger(
      v, "min_covisible_points", min_covisible_points, 1, 1000000,
      "E[i][j] = inf when fewer than max(points, ratio * |X_i|) points of X_i are visible in j");
  visitReal(v, "min_covisible_ratio", min_covisible_ratio, 0.0, 1.0,
            "the same gate's share of X_i");
  visitReal(v, "max_view_angle_deg", max_view_angle_deg, 0.0, 180.0,
            "optional gate on the angle between optical axes [deg]; 0 = off (the paper's mode)");
  occlusion.visitParameters(v);
}

void ErrorResistanceConfig::applyGate() {
  if (gate != Gate::kPaper) return;
  // The paper's behaviour, exactly version 1 of METHOD.md.
  max_parallax_deg = 0.0;
  max_scale_ratio = 0.0;
  min_covisible_points = 10;
  min_covisible_ratio = 0.1;
  max_view_angle_deg = 0.0;
}

void ErrorResistanceConfig::validate() const {
  checkRanges(*this);
  if (max_scale_ratio != 0.0 && max_scale_ratio < 1.0)
    throw InvalidArgument("max_scale_ratio = " + formatNumber(max_scale_ratio) +
                          " must be 0 (off) or at least 1");
}

void validateKeyframe(const Keyframe& keyframe) {
  const PinholeIntrinsics& k = keyframe.intrinsics;
  if (!k.isValid())
    throw InvalidInput("keyframe intrinsics are invalid (fx=" + std::to_string(k.fx) +
                       ", fy=" + std::to_string(k.fy) + ", size " + std::to_string(k.width) + "x" +
                       std::to_string(k.height) + ")");
  if (!keyframe.pose.isValid())
    throw InvalidInput("keyframe pose is not finite or its quaternion is not of unit length");
  if (!keyframe.points.allFinite()) throw InvalidInput("keyframe has non-finite sample points");
  if (keyframe.depth && !keyframe.depth->isConsistent())
    throw InvalidInput(
        "keyframe depth map is inconsistent (size does not match cols x rows, or a cell or depth "
        "is not a positive finite number)");
}

namespace {

/// Smallest sphere-ish bound of the points order[begin, end): centre of the bounding box,
/// radius to the farthest point.
void boundingSphere(const Eigen::Matrix3Xd& points, const std::vector<std::uint32_t>& order,
                    std::uint32_t begin, std::uint32_t end, Eigen::Vector3d& centre, double& radius) {
  Eigen::Vector3d lo = points.col(order[begin]), hi = lo;
  for (std::uint32_t q = begin + 1; q < end; ++q) {
    lo = lo.cwiseMin(points.col(order[q]));
    hi = hi.cwiseMax(points.col(order[q]));
  }
  centre = 0.5 * (lo + hi);
  radius = 0.0;
  for (std::uint32_t q = begin; q < end; ++q)
    radius = std::max(radius, (points.col(order[q]) - centre).norm());
}

/// Splits order[begin, end) at the median of its points' widest axis until groups are small.
void buildGroups(const Eigen::Matrix3Xd& points, std::vector<std::uint32_t>& order,
                 std::uint32_t begin, std::uint32_t end,
                 std::vector<ErrorResistanceMatrix::PointGroup>& groups) {
  ErrorResistanceMatrix::PointGroup group;
  group.begin = begin;
  group.end = end;
  boundingSphere(points, order, begin, end, group.centre, group.radius);
  if (end - begin <= ErrorResistanceMatrix::kGroupSize) {
    groups.push_back(group);
    return;
  }
  Eigen::Vector3d lo = points.col(order[begin]), hi = lo;
  for (std::uint32_t q = begin + 1; q < end; ++q) {
    lo = lo.cwiseMin(points.col(order[q]));
    hi = hi.cwiseMax(points.col(order[q]));
  }
  Eigen::Index axis = 0;
  (hi - lo).maxCoeff(&axis);
  const auto first = order.begin() + begin;
  const auto mid = first + (end - begin) / 2;
  std::nth_element(first, mid, order.begin() + end, [&](std::uint32_t a, std::uint32_t b) {
    return points(axis, a) < points(axis, b) || (points(axis, a) == points(axis, b) && a < b);
  });
  const std::uint32_t split = begin + (end - begin) / 2;
  buildGroups(points, order, begin, split, groups);
  buildGroups(points, order, split, end, groups);
}

/// True when a sphere (centre in camera coordinates) lies wholly outside one frustum plane.
/// The margin keeps the test conservative under rounding.
bool outsideFrustum(const Eigen::Matrix<double, 3, 5>& normals, const Eigen::Vector3d& centre,
                    double radius) {
  const double margin = radius + 1e-9 * (centre.norm() + radius);
  return (normals.transpose() * centre).minCoeff() < -margin;
}

/// METHOD.md's matchable test (version 2) for the points of one ordered pair i -> j, in camera-j
/// coordinates, and a bound on it over a sphere of points, for culling before projecting.
class MatchableTest {
 public:
  MatchableTest(const ErrorResistanceConfig& config, const Eigen::Vector3d& o_i_cam,
                const PinholeIntrinsics& k_i, const PinholeIntrinsics& k_j)
      : parallax_(config.max_parallax_deg > 0.0),
        scale_(config.max_scale_ratio > 0.0),
        cos_max_parallax_(std::cos(config.max_parallax_deg * M_PI / 180.0)),
        max_ratio_(config.max_scale_ratio),
        focal_ratio_(std::sqrt(k_i.fx * k_i.fy) / std::sqrt(k_j.fx * k_j.fy)),
        o_i_(o_i_cam),
        baseline_sq_(o_i_cam.squaredNorm()) {}

  bool active() const { return parallax_ || scale_; }

  /// X (camera-j coordinates) is matchable: the angle at X between the rays to O_i and O_j is
  /// at most max_parallax_deg, and s = (|O_j X| / f_j) / (|O_i X| / f_i) has max(s, 1/s) at most
  /// max_scale_ratio.
  bool passes(const Eigen::Vector3d& x) const {
    const Eigen::Vector3d to_i = o_i_ - x;  // X -> O_i; X -> O_j is -x
    const double d_j = x.norm(), d_i = to_i.norm();
    if (parallax_ && !(-x.dot(to_i) >= cos_max_parallax_ * d_i * d_j)) return false;
    if (scale_) {
      const double s = d_j / d_i * focal_ratio_;
      if (!(s <= max_ratio_ && s * max_ratio_ >= 1.0)) return false;
    }
    return true;
  }

  /// False only when no point within `radius` of `centre` (camera-j coordinates) can pass: from
  /// the ranges of |O_i X| and |O_j X| over the sphere, a lower bound on the parallax (law of
  /// cosines) and the range of the footprint ratio.
  bool mayPass(const Eigen::Vector3d& centre, double radius) const {
    if (!active() || radius < 0.0) return true;
    const double cj = centre.norm(), ci = (o_i_ - centre).norm();
    const double margin = radius + 1e-9 * (cj + ci + radius);  // conservative under rounding
    const double dj_lo = cj - margin, dj_hi = cj + margin;
    const double di_lo = ci - margin, di_hi = ci + margin;
    if (!(dj_lo > 0.0) || !(di_lo > 0.0)) return true;  // a camera may be inside: no bound
    if (scale_) {
      const double s_lo = dj_lo / di_hi * focal_ratio_, s_hi = dj_hi / di_lo * focal_ratio_;
      if (s_lo * (1.0 - 1e-12) > max_ratio_ || s_hi * (1.0 + 1e-12) * max_ratio_ < 1.0)
        return false;
    }
    if (parallax_) {
      // cos(gamma) = (rho + 1/rho) / 2 - B^2 / (2 d_i d_j), rho = d_i / d_j: bounded above by
      // the larger end of rho's range and the largest product.
      const double rho_lo = di_lo / dj_hi, rho_hi = di_hi / dj_lo;
      const double f = 0.5 * std::max(rho_lo + 1.0 / rho_lo, rho_hi + 1.0 / rho_hi);
      const double cos_upper = f - baseline_sq_ / (2.0 * di_hi * dj_hi);
      if (cos_upper + 1e-12 < cos_max_parallax_) return false;
    }
    return true;
  }

 private:
  bool parallax_, scale_;
  double cos_max_parallax_, max_ratio_, focal_ratio_;
  Eigen::Vector3d o_i_;
  double baseline_sq_;
};

}  // namespace

namespace {
std::atomic<std::uint64_t> next_keyframe_version{1};
}  // namespace

ErrorResistanceMatrix::View ErrorResistanceMatrix::makeView(Keyframe keyframe) {
  View v;
  keyframe.pose.orientation.normalize();
  v.world_to_camera = keyframe.pose.rotation().transpose();
  const PinholeIntrinsics& k = keyframe.intrinsics;
  // Inward normals of the planes bounding the visible region [0, w) x [0, h), z > 0.
  v.frustum_normals.col(0) = Eigen::Vector3d(0.0, 0.0, 1.0);
  v.frustum_normals.col(1) = Eigen::Vector3d(k.fx, 0.0, k.cx).normalized();
  v.frustum_normals.col(2) = Eigen::Vector3d(-k.fx, 0.0, k.width - k.cx).normalized();
  v.frustum_normals.col(3) = Eigen::Vector3d(0.0, k.fy, k.cy).normalized();
  v.frustum_normals.col(4) = Eigen::Vector3d(0.0, -k.fy, k.height - k.cy).normalized();
  v.focal = std::sqrt(k.fx * k.fy);
  const auto count = static_cast<std::uint32_t>(keyframe.points.cols());
  if (count > 0) {
    v.point_order.resize(count);
    for (std::uint32_t q = 0; q < count; ++q) v.point_order[q] = q;
    boundingSphere(keyframe.points, v.point_order, 0, count, v.sphere_centre, v.sphere_radius);
    buildGroups(keyframe.points, v.point_order, 0, count, v.groups);
    v.reach = (keyframe.points.colwise() - keyframe.pose.position).colwise().norm().maxCoeff();
  } else {
    v.sphere_centre.setZero();
    v.sphere_radius = -1.0;
  }
  v.keyframe = std::move(keyframe);
  v.version = next_keyframe_version.fetch_add(1, std::memory_order_relaxed);
  return v;
}

std::uint64_t ErrorResistanceMatrix::lastKeyframeVersionIssued() {
  return next_keyframe_version.load(std::memory_order_relaxed) - 1;
}

void ErrorResistanceMatrix::placed(ViewId id) {
  const size_t chunk = static_cast<size_t>(id) / ErrorResistanceTable::kVersionChunk;
  if (chunk >= keyframe_chunk_version_.size()) keyframe_chunk_version_.resize(chunk + 1, 0);
  keyframe_chunk_version_[chunk] =
      std::max(keyframe_chunk_version_[chunk], views_[static_cast<size_t>(id)].version);
}

double computeErrorResistance(const ErrorResistanceMatrix::View& view_i,
                              const ErrorResistanceMatrix::View& view_j,
                              const ErrorResistanceConfig& config,
                              ErrorResistanceMatrix::Scratch& scratch, bool* evaluated) {
  if (evaluated) *evaluated = false;
  const Keyframe& kf_i = view_i.keyframe;
  const Keyframe& kf_j = view_j.keyframe;
  const Eigen::Index n_points = kf_i.points.cols();
  const double needed = std::max(static_cast<double>(config.min_covisible_points),
                                 config.min_covisible_ratio * static_cast<double>(n_points));
  if (static_cast<double>(n_points) < needed) return kInfinity;

  if (config.max_view_angle_deg > 0.0) {
    const double c =
        std::clamp(view_i.world_to_camera.row(2).dot(view_j.world_to_camera.row(2)), -1.0, 1.0);
    if (std::acos(c) * 180.0 / M_PI > config.max_view_angle_deg) return kInfinity;
  }

  const Eigen::Matrix3d& r_cw = view_j.world_to_camera;
  const Eigen::Vector3d& o_j = kf_j.pose.position;
  // Pair-level culls: no point can count when X_i's bounding sphere is outside j's frustum (the
  // cheap test, first: most pairs of a long sequence end here), or when no point in it can be
  // matchable.
  const Eigen::Vector3d sphere_cam = r_cw * (view_i.sphere_centre - o_j);
  if (outsideFrustum(view_j.frustum_normals, sphere_cam, view_i.sphere_radius)) return kInfinity;
  const MatchableTest matchable(config, r_cw * (kf_i.pose.position - o_j), kf_i.intrinsics,
                                kf_j.intrinsics);
  if (!matchable.mayPass(sphere_cam, view_i.sphere_radius)) return kInfinity;
  // Group-level cull: keep the groups that may count; stop early when they cannot hold
  // enough points to pass the co-visibility gate.
  auto& candidates = scratch.groups;
  candidates.clear();
  Eigen::Index possible = 0;
  for (const auto& g : view_i.groups) {
    const Eigen::Vector3d centre_cam = r_cw * (g.centre - o_j);
    if (outsideFrustum(view_j.frustum_normals, centre_cam, g.radius) ||
        !matchable.mayPass(centre_cam, g.radius))
      continue;
    candidates.push_back(&g);
    possible += static_cast<Eigen::Index>(g.end - g.begin);
  }
  if (static_cast<double>(possible) < needed) return kInfinity;
  if (evaluated) *evaluated = true;

  const PinholeIntrinsics& k = kf_j.intrinsics;
  const DepthMap* depth = kf_j.depth ? kf_j.depth.get() : nullptr;
  const double width = k.width, height = k.height;
  scratch.x.clear();
  scratch.y.clear();
  scratch.z.clear();
  // Points not yet looked at; when they cannot lift the visible count to the gate, stop.
  Eigen::Index unseen = possible;
  for (const auto* g : candidates) {
    if (static_cast<double>(scratch.x.size() + static_cast<size_t>(unseen)) < needed)
      return kInfinity;
    unseen -= static_cast<Eigen::Index>(g->end - g->begin);
    for (std::uint32_t c = g->begin; c < g->end; ++c) {
      const Eigen::Vector3d p = r_cw * (kf_i.points.col(view_i.point_order[c]) - o_j);
      if (!(p.z() > 0.0)) continue;
      const double inv_z = 1.0 / p.z();
      const double u = k.fx * p.x() * inv_z + k.cx;
      const double v = k.fy * p.y() * inv_z + k.cy;
      if (!(u >= 0.0 && v >= 0.0 && u < width && v < height)) continue;
      // Occluded (or in front of the surface j saw): not visible.
      if (depth && occluded(*depth, u, v, p.z(), config.occlusion)) continue;
      if (matchable.active() && !matchable.passes(p)) continue;
      scratch.x.push_back(p.x());
      scratch.y.push_back(p.y());
      scratch.z.push_back(p.z());
    }
  }
  const size_t count = scratch.x.size();
  if (static_cast<double>(count) < needed) return kInfinity;

  const PairErrorResistance resistance(kf_i.pose.position, k, kf_j.pose);
  scratch.values.resize(count);
  resistance.evaluate(scratch.x.data(), scratch.y.data(), scratch.z.data(), count,
                      scratch.values.data());

  // Median; for an even count the mean of the two middle values (+inf if either is +inf).
  auto& vals = scratch.values;
  const size_t mid = vals.size() / 2;
  std::nth_element(vals.begin(), vals.begin() + static_cast<std::ptrdiff_t>(mid), vals.end());
  double median = vals[mid];
  if (vals.size() % 2 == 0) {
    const double lower =
        *std::max_element(vals.begin(), vals.begin() + static_cast<std::ptrdiff_t>(mid));
    median = std::isfinite(median) ? 0.5 * (lower + median) : kInfinity;
  }
  return std::isfinite(median) ? median : kInfinity;
}

double computeErrorResistance(const Keyframe& view_i, const Keyframe& view_j,
                              const ErrorResistanceConfig& config) {
  ErrorResistanceMatrix::Scratch scratch;
  return computeErrorResistance(ErrorResistanceMatrix::makeView(view_i),
                                ErrorResistanceMatrix::makeView(view_j), config.inForce(), scratch);
}

ErrorResistanceMatrix::ErrorResistanceMatrix(ErrorResistanceConfig config)
    : config_(config.inForce()) {
  config_.validate();
}

double ErrorResistanceMatrix::entry(const View& view_i, const View& view_j) {
  bool evaluated = false;
  const double value = computeErrorResistance(view_i, view_j, config_, scratch_, &evaluated);
  pairs_evaluated_ += evaluated ? 1 : 0;
  return value;
}

void ErrorResistanceMatrix::candidates(ViewId id, bool row, std::vector<ViewId>& out) {
  const View& v = views_[static_cast<size_t>(id)];
  out.clear();
  const double ratio = config_.max_scale_ratio;
  if (!(ratio > 0.0) || v.focal <= 0.0) {
    // No footprint-ratio gate: no distance bound, every other view is a candidate (O(n)).
    for (size_t j = 0; j < views_.size(); ++j)
      if (static_cast<ViewId>(j) != id) out.push_back(static_cast<ViewId>(j));
    candidates_examined_ += views_.size();
    return;
  }
  // A point X of X_i counts in j only when |O_j X| <= ratio |O_i X| f_j / f_i, so
  // |O_i O_j| <= |O_i X| + |O_j X| <= reach_i (1 + ratio f_j / f_i): pairs farther apart are +inf.
  const Eigen::Vector3d& centre = v.keyframe.pose.position;
  const double slack = 1.0 + 1e-9;
  if (row) {  // X_id in the others
    grid_.query(centre, slack * v.reach * (1.0 + ratio * max_focal_ / v.focal), out);
    candidates_examined_ += grid_.lastExamined();
  } else {  // the others' points in id: bound by the grid's reach, then each by its own
    grid_.query(centre, slack * grid_reach_ * (1.0 + ratio * v.focal / min_focal_), out);
    candidates_examined_ += grid_.lastExamined();
    // The farthest-reaching views (beyond grid_reach_) one by one.
    size_t far = 0;
    for (auto it = reaches_.rbegin(); it != reaches_.rend() && it->first > grid_reach_; ++it) {
      out.push_back(it->second);
      ++far;
    }
    candidates_examined_ += far;
    if (far > 0) {
      std::sort(out.begin(), out.end());
      out.erase(std::unique(out.begin(), out.end()), out.end());
    }
    out.erase(std::remove_if(out.begin(), out.end(),
                             [&](ViewId i) {
                               const View& w = views_[static_cast<size_t>(i)];
                               const double bound = slack * w.reach * (1.0 + ratio * v.focal / w.focal);
                               return (w.keyframe.pose.position - centre).norm() > bound;
                             }),
              out.end());
  }
  out.erase(std::remove(out.begin(), out.end(), id), out.end());
}

std::vector<TableEntry> ErrorResistanceMatrix::computeRow(ViewId id) {
  std::vector<TableEntry> row;
  std::vector<ViewId> others;
  candidates(id, true, others);
  const View& v = views_[static_cast<size_t>(id)];
  for (const ViewId j : others) {
    const double value = entry(v, views_[static_cast<size_t>(j)]);
    if (std::isfinite(value)) row.push_back({j, value});
  }
  return row;
}

double ErrorResistanceMatrix::countedReach(const View& v) const {
  // E[i][j] is finite only when at least m points of X_i count in j, and a point X counts only
  // when |O_i O_j| <= |O_i X| (1 + ratio f_j / f_i): so |O_i O_j| is bounded by the m-th
  // farthest point, not the farthest (a few far points do not widen the search).
  const Keyframe& k = v.keyframe;
  const Eigen::Index n = k.points.cols();
  const double needed = std::max(static_cast<double>(config_.min_covisible_points),
                                 config_.min_covisible_ratio * static_cast<double>(n));
  const auto m = static_cast<Eigen::Index>(std::max(1.0, std::ceil(needed)));
  if (n < m) return 0.0;  // no entry of its row can be finite
  std::vector<double> d(static_cast<size_t>(n));
  for (Eigen::Index c = 0; c < n; ++c)
    d[static_cast<size_t>(c)] = (k.points.col(c) - k.pose.position).norm();
  std::nth_element(d.begin(), d.begin() + (m - 1), d.end(), std::greater<double>());
  return d[static_cast<size_t>(m - 1)];
}

void ErrorResistanceMatrix::setReach(ViewId id, double reach) {
  View& v = views_[static_cast<size_t>(id)];
  const auto [from, to] = reaches_.equal_range(v.reach);
  for (auto it = from; it != to; ++it)
    if (it->second == id) {
      reaches_.erase(it);
      break;
    }
  v.reach = reach;
  reaches_.emplace(reach, id);
  updateGridReach();
}

void ErrorResistanceMatrix::updateGridReach() {
  // The kFarViews farthest-reaching views are looked at one by one; the grid is searched with
  // the next one's reach, so a few outliers never widen every search.
  auto it = reaches_.rbegin();
  for (size_t q = 0; q < kFarViews && it != reaches_.rend(); ++q) ++it;
  grid_reach_ = it == reaches_.rend() ? 0.0 : it->first;
}

void ErrorResistanceMatrix::index(ViewId id) {
  View& v = views_[static_cast<size_t>(id)];
  v.reach = countedReach(v);
  reaches_.emplace(v.reach, id);
  placed(id);
  updateGridReach();
  min_focal_ = id == 0 ? v.focal : std::min(min_focal_, v.focal);
  max_focal_ = std::max(max_focal_, v.focal);
  grid_.insert(id, v.keyframe.pose.position);
}

ViewId ErrorResistanceMatrix::addKeyframe(Keyframe keyframe) {
  validateKeyframe(keyframe);
  names_.push(views_.size(), keyframe.stamp, keyframe.image_name);
  summaries_.push_back(KeyframeSummary::of(keyframe));
  views_.push_back(makeView(std::move(keyframe)));
  const auto n = static_cast<ViewId>(views_.size() - 1);
  table_.resize(views_.size());
  const View& added = views_.back();
  index(n);
  candidates(n, true, candidates_);
  for (const ViewId j : candidates_) table_.set(n, j, entry(added, views_[static_cast<size_t>(j)]));
  candidates(n, false, candidates_);
  for (const ViewId i : candidates_) table_.set(i, n, entry(views_[static_cast<size_t>(i)], added));
  return n;
}

void ErrorResistanceMatrix::setPoints(ViewId id, Eigen::Matrix3Xd points) {
  if (id < 0 || static_cast<size_t>(id) >= views_.size())
    throw InvalidArgument("setPoints: unknown view id " + std::to_string(id));
  if (!points.allFinite()) throw InvalidInput("setPoints: non-finite sample points");
  const double old_reach = views_[static_cast<size_t>(id)].reach;
  Keyframe keyframe = std::move(views_[static_cast<size_t>(id)].keyframe);
  keyframe.points = std::move(points);
  views_[static_cast<size_t>(id)] = makeView(std::move(keyframe));
  summaries_.edit(static_cast<size_t>(id)).num_points =
      static_cast<size_t>(views_[static_cast<size_t>(id)].keyframe.points.cols());
  // The old reach leaves the bound (a far point replaced: the search narrows again).
  const double reach = countedReach(views_[static_cast<size_t>(id)]);
  views_[static_cast<size_t>(id)].reach = old_reach;
  setReach(id, reach);
  placed(id);
  table_.replaceRow(id, computeRow(id));
}

void ErrorResistanceMatrix::setConfig(const ErrorResistanceConfig& requested) {
  const ErrorResistanceConfig config = requested.inForce();
  config.validate();
  if (config == config_) return;
  config_ = config;
  // The reach bound depends on the co-visibility gate.
  for (size_t i = 0; i < views_.size(); ++i)
    setReach(static_cast<ViewId>(i), countedReach(views_[i]));
  for (size_t i = 0; i < views_.size(); ++i)
    table_.replaceRow(static_cast<ViewId>(i), computeRow(static_cast<ViewId>(i)));
}

void ErrorResistanceMatrix::restore(std::vector<Keyframe> keyframes,
                                    const std::vector<std::vector<TableEntry>>& rows) {
  if (rows.size() != keyframes.size())
    throw InvalidInput("saved matrix has " + std::to_string(rows.size()) + " rows for " +
                       std::to_string(keyframes.size()) + " keyframes");
  const size_t n = keyframes.size();
  for (size_t i = 0; i < n; ++i) {
    validateKeyframe(keyframes[i]);
    std::vector<bool> seen(n, false);
    for (const TableEntry& e : rows[i]) {
      if (e.view < 0 || static_cast<size_t>(e.view) >= n || static_cast<size_t>(e.view) == i ||
          seen[static_cast<size_t>(e.view)] || !std::isfinite(e.value) || e.value < 0.0)
        throw InvalidInput("saved matrix row " + std::to_string(i) +
                           " has an invalid entry (column " + std::to_string(e.view) + ")");
      seen[static_cast<size_t>(e.view)] = true;
    }
  }
  std::vector<View> views;
  views.reserve(n);
  ChunkedVector<KeyframeSummary> summaries;
  ImageNames names;
  for (Keyframe& k : keyframes) {
    names.push(views.size(), k.stamp, k.image_name);
    summaries.push_back(KeyframeSummary::of(k));
    views.push_back(makeView(std::move(k)));
  }
  ErrorResistanceTable table(n);
  for (size_t i = 0; i < n; ++i) table.replaceRow(static_cast<ViewId>(i), rows[i]);
  views_ = std::move(views);
  summaries_ = std::move(summaries);
  names_ = std::move(names);
  table_ = std::move(table);
  pairs_evaluated_ = 0;
  // What insertion's candidate search needs of the views so far.
  grid_.clear();
  reaches_.clear();
  keyframe_chunk_version_.clear();
  grid_reach_ = min_focal_ = max_focal_ = 0.0;
  for (size_t i = 0; i < views_.size(); ++i) index(static_cast<ViewId>(i));
}

Keyframe movedKeyframe(Keyframe keyframe, CameraPose pose) {
  pose.orientation.normalize();
  CameraPose old = keyframe.pose;
  old.orientation.normalize();
  // world' = R' R^T (world - c) + c': the camera-frame coordinates stay.
  const Eigen::Matrix3d relative = pose.rotation() * old.rotation().transpose();
  for (Eigen::Index c = 0; c < keyframe.points.cols(); ++c)
    keyframe.points.col(c) = relative * (keyframe.points.col(c) - old.position) + pose.position;
  keyframe.pose = pose;
  return keyframe;
}

void ErrorResistanceMatrix::setPoses(const std::vector<std::pair<ViewId, CameraPose>>& poses) {
  std::vector<char> moved(views_.size(), 0);
  for (const auto& [id, pose] : poses) {
    if (id < 0 || static_cast<size_t>(id) >= views_.size())
      throw InvalidArgument("setPoses: unknown view id " + std::to_string(id));
    if (moved[static_cast<size_t>(id)])
      throw InvalidArgument("setPoses: view " + std::to_string(id) + " given twice");
    if (!pose.isValid())
      throw InvalidInput("setPoses: invalid pose for view " + std::to_string(id));
    moved[static_cast<size_t>(id)] = 1;
  }
  for (const auto& [id, pose] : poses) {
    View& view = views_[static_cast<size_t>(id)];
    const double reach = view.reach;  // counted; a rigid motion keeps it
    view = makeView(movedKeyframe(std::move(view.keyframe), pose));
    view.reach = reach;
    placed(id);
    summaries_.edit(static_cast<size_t>(id)).pose = view.keyframe.pose;
    // A rigid motion keeps a view's reach and focal length; only its centre moves in the grid.
    grid_.move(id, view.keyframe.pose.position);
  }
  // Rows of the moved keyframes in full (over their candidates, as insertion does); of the
  // others, only the moved keyframes' columns.
  for (const auto& [id, pose] : poses) table_.replaceRow(id, computeRow(id));
  std::vector<ViewId> rows;
  for (const auto& [id, pose] : poses) {
    // The candidates now, and every row whose entry was finite before (it may have become
    // +inf); most entries are +inf before and after, and the table is touched only where one is
    // finite.
    const std::vector<TableEntry> before = table_.column(id);  // ascending row
    candidates(id, false, candidates_);
    rows.clear();
    std::vector<TableEntry>::const_iterator b = before.begin();
    for (const ViewId i : candidates_) {
      for (; b != before.end() && b->view < i; ++b) rows.push_back(b->view);
      if (b != before.end() && b->view == i) ++b;
      rows.push_back(i);
    }
    for (; b != before.end(); ++b) rows.push_back(b->view);
    const View& changed = views_[static_cast<size_t>(id)];
    size_t k = 0;
    for (const ViewId i : rows) {
      if (moved[static_cast<size_t>(i)]) continue;
      const double value = entry(views_[static_cast<size_t>(i)], changed);
      while (k < before.size() && before[k].view < i) ++k;
      const bool was_finite = k < before.size() && before[k].view == i;
      if (was_finite || std::isfinite(value)) table_.set(i, id, value);
    }
  }
}

void ErrorResistanceMatrix::clear() {
  views_.clear();
  summaries_.clear();
  names_.clear();
  table_.clear();
  pairs_evaluated_ = 0;
  grid_.clear();
  reaches_.clear();
  keyframe_chunk_version_.clear();
  grid_reach_ = min_focal_ = max_focal_ = 0.0;
}

}  // namespace view_selection::core
