#include "view_selection/core/keyframe_policy.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>

namespace view_selection::core {

void KeyframePolicyConfig::visitParameters(ParameterVisitor& v) {
  v.section("Keyframes (select_views: --every, --min-translation, --min-rotation)");
  visitChoice(v, "keyframe_policy", mode, kKeyframeModeNames,
              "which frames become keyframes: every_frame, every_nth, motion (after enough "
              "translation or rotation), or external (the node only: the stamps on `keyframes`, "
              "e.g. a SLAM system's keyframe path)");
  visitInteger(v, "every_n", every_n, 1, 1000000, "every_nth: one keyframe every N valid frames");
  visitReal(v, "min_translation", min_translation, 0.0, 1e9,
            "motion: a new keyframe after this much translation [m, scene units] ...");
  visitReal(v, "min_rotation_deg", min_rotation_deg, 0.0, 360.0,
            "... or this much rotation since the last keyframe [deg]");
}

KeyframePolicy::KeyframePolicy(KeyframePolicyConfig config) : config_(config) {
  config_.validate();
}

bool KeyframePolicy::offer(const CameraPose& pose, bool external) {
  const long index = frames_offered_++;
  switch (config_.mode) {
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
