// Which frames become keyframes: every frame, every Nth frame, after enough motion, or as an
// outside decision (the SLAM system's keyframes) says.
#pragma once

#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <optional>
#include <string>

namespace view_selection::core {

enum class KeyframeMode {
  kEveryFrame,  ///< every frame offered
  kEveryNth,    ///< frames 0, N, 2N, ... of those offered
  kMotion,      ///< the first frame, then one after min_translation OR min_rotation_deg of motion
  kExternal,    ///< the caller's verdict for each frame (Frame::external_keyframe)
};

inline constexpr EnumNames<KeyframeMode, 4> kKeyframeModeNames{
    {{KeyframeMode::kEveryFrame, "every_frame"},
     {KeyframeMode::kEveryNth, "every_nth"},
     {KeyframeMode::kMotion, "motion"},
     {KeyframeMode::kExternal, "external"}}};

inline std::string toString(KeyframeMode mode) { return nameOf(mode, kKeyframeModeNames); }
/// "every_frame", "every_nth" or "motion"; throws InvalidArgument otherwise.
inline KeyframeMode keyframeModeFromString(const std::string& text) {
  return valueOf(text, kKeyframeModeNames, "keyframe_policy");
}

struct KeyframePolicyConfig {
  KeyframeMode mode = KeyframeMode::kMotion;
  int every_n = 10;                ///< kEveryNth: keep one frame in every_n
  double min_translation = 0.10;   ///< kMotion: [m, scene units] since the last keyframe
  double min_rotation_deg = 10.0;  ///< kMotion: [deg] since the last keyframe

  void visitParameters(ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const { checkRanges(*this); }
};

class KeyframePolicy {
 public:
  explicit KeyframePolicy(KeyframePolicyConfig config = {});

  /// Offers the next frame; true when it should become a keyframe. Counts the frame either way.
  /// The policy remembers the pose only once the caller confirms with keyframeAccepted(), so a
  /// frame that is dropped later (no points, bad depth) does not move the reference.
  /// `external`: the verdict in kExternal mode (ignored otherwise).
  bool offer(const CameraPose& pose, bool external = false);
  /// The frame offered last did become a keyframe at `pose`.
  void keyframeAccepted(const CameraPose& pose);
  void reset();
  /// New thresholds from the next frame on; the last keyframe and the frame count stay.
  void setConfig(const KeyframePolicyConfig& config) {
    config.validate();
    config_ = config;
  }
  const KeyframePolicyConfig& config() const { return config_; }

  /// Where the policy is: what a saved session needs to continue exactly.
  struct State {
    long frames_offered = 0;                  ///< frames offered so far (every_nth counts them)
    std::optional<CameraPose> last_keyframe;  ///< motion: the reference pose
  };
  State state() const { return {frames_offered_, last_keyframe_}; }
  /// Continues from `state` (throws InvalidInput for a negative count or an invalid pose).
  void restore(const State& state);

 private:
  KeyframePolicyConfig config_;
  long frames_offered_ = 0;
  std::optional<CameraPose> last_keyframe_;
};

}  // namespace view_selection::core
