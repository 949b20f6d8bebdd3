#include "view_selection/core/keyframe_policy.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace view_selection::core {

void KeyframePolicyConfig::visitParameters(ParameterVisitor& v) {
  v.section("Keyframes (select_views: --keyframe-policy, --every, --min-translation, --min-rotation)");
  visitChoice(v, "keyframe_policy", mode, kKeyframeModeNames,
              "which frames become keyframes: scale_free (when the view of the last keyframe's "
              "points has changed enough; the same in any unit), every_frame, every_nth, motion "
              "(after enough translation or rotation, in scene units), or external (the node "
              "only: the stamps on `keyframes`, e.g. a SLAM system's keyframe path)");
  visitReal(v, "keyframe_overlap", keyframe_overlap, 0.0, 1.0,
            "scale_free: a new keyframe when fewer than this share of the last keyframe's points "
            "are matchable in the frame ...");
  visitReal(v, "keyframe_parallax_deg", keyframe_parallax_deg, 0.0, 180.0,
            "... or when the parallax at the nearer of them (90th percentile) reaches this "
            "[deg]; 0 = off");
  visitFlag(v, "revisit_registration", revisit_registration,
            "scale_free: a frame the poses place on no earlier keyframe's view is registered "
            "from its image (ORB, PnP) to the most alike earlier keyframes and measured again at "
            "the registered pose, so that a revisit is recognised under drift; needs images and "
            "keyframes with depth. The keyframe made where such a revisit ends names the keyframe "
            "it revisits (revisit_of), a pair across the drift for colmap_bridge's loop pairs");
  visitInteger(v, "every_n", every_n, 1, 1000000, "every_nth: one keyframe every N valid frames");
  visitReal(v, "min_translation", min_translation, 0.0, 1e9,
            "motion: a new keyframe after this much translation [scene units: m when the poses "
            "are in m] ...");
  visitReal(v, "min_rotation_deg", min_rotation_deg, 0.0, 360.0,
            "... or this much rotation since the last keyframe [deg]");
}

ViewChange measureViewChange(const Eigen::Matrix3Xd& points, const Eigen::Vector3d& reference,
                             double reference_focal, const CameraPose& pose,
                             const PinholeIntrinsics& k, double max_parallax_deg,
                             double max_scale_ratio) {
  ViewChange c;
  c.points = static_cast<size_t>(points.cols());
  if (points.cols() == 0) return c;
  const Eigen::Matrix3d world_to_camera = pose.rotation().transpose();
  const double cos_max_parallax =
      max_parallax_deg > 0.0 ? std::cos(max_parallax_deg * M_PI / 180.0) : -2.0;
  const double focal = std::sqrt(k.fx * k.fy);
  std::vector<double> cosines;
  cosines.reserve(static_cast<size_t>(points.cols()));
  for (Eigen::Index q = 0; q < points.cols(); ++q) {
    const Eigen::Vector3d x = points.col(q);
    const Eigen::Vector3d p = world_to_camera * (x - pose.position);
    if (!(p.z() > 0.0) || !k.inImage(k.project(p))) continue;
    ++c.visible;
    const Eigen::Vector3d to_ref = reference - x, to_frame = pose.position - x;
    const double d_ref = to_ref.norm(), d_frame = to_frame.norm();
    // A camera on the point: no angle; counts as the widest parallax.
    const double cosine =
        d_ref > 0.0 && d_frame > 0.0 ? std::clamp(to_ref.dot(to_frame) / (d_ref * d_frame), -1.0, 1.0)
                                     : -1.0;
    cosines.push_back(cosine);
    if (cosine < cos_max_parallax) continue;
    if (max_scale_ratio > 0.0) {
      const double s = (d_frame / focal) / (d_ref / reference_focal);
      if (!(std::max(s, 1.0 / s) <= max_scale_ratio)) continue;
    }
    ++c.matchable;
  }
  c.overlap = static_cast<double>(c.matchable) / static_cast<double>(c.points);
  if (!cosines.empty()) {
    // The parallax of the nearer points: the angle's 90th percentile is the cosine's 10th
    // (acos decreases), the element of rank floor(0.1 (n - 1)) in ascending order.
    const size_t rank = static_cast<size_t>(0.1 * static_cast<double>(cosines.size() - 1));
    std::nth_element(cosines.begin(), cosines.begin() + static_cast<std::ptrdiff_t>(rank),
                     cosines.end());
    c.parallax_deg = std::acos(cosines[rank]) * 180.0 / M_PI;
  }
  return c;
}

std::string describeKeyframeRule(const KeyframePolicyConfig& kf) {
  std::ostringstream s;
  s.precision(6);
  switch (kf.mode) {
    case KeyframeMode::kScaleFree:
      s << "scale_free: a new keyframe when under " << kf.keyframe_overlap
        << " of the last keyframe's points are matchable or the parallax at the nearer of "
           "them (90th percentile) reaches "
        << kf.keyframe_parallax_deg << " deg, unless an earlier keyframe near it has the view";
      break;
    case KeyframeMode::kMotion:
      s << "motion: a new keyframe after " << kf.min_translation
        << " scene units (metres if the poses are in metres) or " << kf.min_rotation_deg
        << " deg";
      break;
    case KeyframeMode::kEveryFrame:
      s << "every frame";
      break;
    case KeyframeMode::kEveryNth:
      s << "every " << kf.every_n << " frames";
      break;
    case KeyframeMode::kExternal:
      s << "external: the frames the keyframe stamps name";
      break;
  }
  return s.str();
}

KeyframePolicy::KeyframePolicy(KeyframePolicyConfig config) : config_(config) {
  config_.validate();
}

bool KeyframePolicy::offer(const CameraPose& pose, bool external,
                           const KeyframeReference* reference,
                           const PinholeIntrinsics* intrinsics, double stamp) {
  const long index = frames_offered_++;
  last_change_.reset();
  switch (config_.mode) {
    case KeyframeMode::kScaleFree: {
      if (!reference) return true;  // the first frame
      if (!reference->points || reference->points->cols() < kMinReferencePoints) {
        // No keyframe has points yet: turned far enough, or long enough after the last one.
        const Eigen::Vector3d a = reference->pose.rotation().col(2), b = pose.rotation().col(2);
        const double turned = std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
        return !std::isfinite(stamp) || !(stamp > reference->stamp) ||
               stamp - reference->stamp >= kNoPointsInterval ||
               (config_.keyframe_parallax_deg > 0.0 && turned >= config_.keyframe_parallax_deg);
      }
      if (!intrinsics) throw InvalidArgument("keyframe policy scale_free needs the frame's intrinsics");
      const ViewChange& c = last_change_.emplace(measureViewChange(
          *reference->points, reference->pose.position,
          std::sqrt(reference->intrinsics.fx * reference->intrinsics.fy), pose, *intrinsics,
          reference->max_parallax_deg, reference->max_scale_ratio));
      return isNewView(c);
    }
    case KeyframeMode::kEveryFrame:
      return true;
    case KeyframeMode::kEveryNth:
      return index % config_.every_n == 0;
    case KeyframeMode::kExternal:
      return external;
    case KeyframeMode::kMotion: {
      if (!last_keyframe_) return true;
      const double moved = (pose.position - last_keyframe_->position).norm();
      const Eigen::Quaterniond a = last_keyframe_->orientation.normalized();
      const Eigen::Quaterniond b = pose.orientation.normalized();
      const double turned_deg = 2.0 * std::acos(std::min(1.0, std::abs(a.dot(b)))) * 180.0 / M_PI;
      return moved >= config_.min_translation || turned_deg >= config_.min_rotation_deg;
    }
  }
  return false;
}

bool KeyframePolicy::isNewView(const ViewChange& c) const {
  return c.overlap < config_.keyframe_overlap ||
         (config_.keyframe_parallax_deg > 0.0 && c.parallax_deg >= config_.keyframe_parallax_deg);
}

bool KeyframePolicy::covers(const KeyframeReference& reference, const CameraPose& pose,
                            const PinholeIntrinsics& intrinsics) const {
  if (!reference.points || reference.points->cols() < kMinReferencePoints) return false;
  const ViewChange c = measureViewChange(
      *reference.points, reference.pose.position,
      std::sqrt(reference.intrinsics.fx * reference.intrinsics.fy), pose, intrinsics,
      reference.max_parallax_deg, reference.max_scale_ratio);
  // At least one point: with keyframe_overlap 0 a keyframe that sees none of it covers nothing.
  return c.matchable > 0 && !isNewView(c);
}

void KeyframePolicy::keyframeAccepted(const CameraPose& pose) { last_keyframe_ = pose; }

void KeyframePolicy::restore(const State& state) {
  if (state.frames_offered < 0) throw InvalidInput("keyframe policy: negative frame count");
  if (state.last_keyframe && !state.last_keyframe->isValid())
    throw InvalidInput("keyframe policy: the last keyframe's pose is invalid");
  frames_offered_ = state.frames_offered;
  last_keyframe_ = state.last_keyframe;
}

void KeyframePolicy::reset() {
  frames_offered_ = 0;
  last_keyframe_.reset();
}

}  // namespace view_selection::core
