#include "view_selection/core/keyframe_policy.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cmath>

namespace view_selection {

std::string toString(KeyframeMode mode) {
  switch (mode) {
    case KeyframeMode::kEveryFrame: return "every_frame";
    case KeyframeMode::kEveryNth: return "every_nth";
    case KeyframeMode::kMotion: return "motion";
  }
  return "unknown";
}

KeyframeMode keyframeModeFromString(const std::string& text) {
  if (text == "every_frame") return KeyframeMode::kEveryFrame;
  if (text == "every_nth") return KeyframeMode::kEveryNth;
  if (text == "motion") return KeyframeMode::kMotion;
  throw InvalidArgument("keyframe mode must be 'every_frame', 'every_nth' or 'motion', got '" +
                        text + "'");
}

void KeyframePolicyConfig::validate() const {
  if (every_n < 1) throw InvalidArgument("every_n must be >= 1, got " + std::to_string(every_n));
  if (!(min_translation >= 0.0) || !std::isfinite(min_translation))
    throw InvalidArgument("min_translation must be >= 0");
  if (!(min_rotation_deg >= 0.0) || !std::isfinite(min_rotation_deg))
    throw InvalidArgument("min_rotation_deg must be >= 0");
}

KeyframePolicy::KeyframePolicy(KeyframePolicyConfig config) : config_(config) {
  config_.validate();
}

bool KeyframePolicy::offer(const CameraPose& pose) {
  const long index = frames_offered_++;
  switch (config_.mode) {
    case KeyframeMode::kEveryFrame:
      return true;
    case KeyframeMode::kEveryNth:
      return index % config_.every_n == 0;
    case KeyframeMode::kMotion: {
      if (!last_keyframe_) return true;
      const double moved = (pose.position - last_keyframe_->position).norm();
      const Eigen::Quaterniond a = last_keyframe_->orientation.normalized();
      const Eigen::Quaterniond b = pose.orientation.normalized();
      const double turned_deg =
          2.0 * std::acos(std::min(1.0, std::abs(a.dot(b)))) * 180.0 / M_PI;
      return moved >= config_.min_translation || turned_deg >= config_.min_rotation_deg;
    }
  }
  return false;
}

void KeyframePolicy::keyframeAccepted(const CameraPose& pose) { last_keyframe_ = pose; }

void KeyframePolicy::reset() {
  frames_offered_ = 0;
  last_keyframe_.reset();
}

}  // namespace view_selection
