// Which frames become keyframes: every frame, every Nth frame, when the view has changed enough
// against the last keyframe's points (scale_free, the default), after enough motion in scene
// units, or as an outside decision (the SLAM system's keyframes) says.
#pragma once

#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace view_selection::core {

enum class KeyframeMode {
  kEveryFrame,  ///< every frame offered
  kEveryNth,    ///< frames 0, N, 2N, ... of those offered
  kMotion,      ///< the first frame, then one after min_translation OR min_rotation_deg of motion
  kExternal,    ///< the caller's verdict for each frame (Frame::external_keyframe)
  /// the first frame, then one whose view of the last keyframe's points has changed enough:
  /// fewer than keyframe_overlap of them matchable, or the parallax of the nearer ones (90th
  /// percentile) at least keyframe_parallax_deg (angles and ratios only: any unit alike), and
  /// no earlier keyframe near it has the view by the same measure (the revisit rule:
  /// ViewSelector::coveringKeyframe, docs/design.md)
  kScaleFree,
};

inline constexpr EnumNames<KeyframeMode, 5> kKeyframeModeNames{
    {{KeyframeMode::kScaleFree, "scale_free"},
     {KeyframeMode::kEveryFrame, "every_frame"},
     {KeyframeMode::kEveryNth, "every_nth"},
     {KeyframeMode::kMotion, "motion"},
     {KeyframeMode::kExternal, "external"}}};

inline std::string toString(KeyframeMode mode) { return nameOf(mode, kKeyframeModeNames); }
/// One of kKeyframeModeNames; throws InvalidArgument otherwise.
inline KeyframeMode keyframeModeFromString(const std::string& text) {
  return valueOf(text, kKeyframeModeNames, "keyframe_policy");
}

struct KeyframePolicyConfig {
  KeyframeMode mode = KeyframeMode::kScaleFree;
  int every_n = 10;                ///< kEveryNth: keep one frame in every_n
  double min_translation = 0.10;   ///< kMotion: [scene units, m for TUM] since the last keyframe
  double min_rotation_deg = 10.0;  ///< kMotion: [deg] since the last keyframe
  /// kScaleFree: a new keyframe when fewer than this share of the last keyframe's points are
  /// matchable in the frame (visible, parallax at most 20 deg, footprint ratio within 1.6: the
  /// matchable gate's defaults, fixed) ...
  double keyframe_overlap = 0.8;
  /// ... or when the parallax at the nearer of its points the frame sees (the 90th percentile
  /// over them) reaches this [deg]; 0: off. Both chosen by measurement (docs/results.md).
  double keyframe_parallax_deg = 5.0;
  /// kScaleFree's revisit rule: when the poses find no earlier keyframe that has the frame's
  /// view, the frame is registered from its image to the most alike earlier keyframes (not the
  /// last ViewSelector::kRecentSeconds) and measured again at the registered pose, so that a
  /// revisit is recognised where drift put it off its first pass
  /// (ViewSelector::registeredCoveringKeyframe; only where the caller gave the selector a
  /// FrameRegistration: the node, select_views). The keyframe made where such a revisit ends is
  /// linked to the keyframe it revisits (Keyframe::revisit_of), the pair across the drift that
  /// the refinement needs (docs/design.md, "Revisits under drift").
  bool revisit_registration = true;

  void visitParameters(ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const { checkRanges(*this); }
};

/// How a frame sees the points of a reference keyframe (the scale_free policy's measure).
struct ViewChange {
  size_t points = 0;         ///< reference points
  size_t visible = 0;        ///< in front of the frame and inside its image
  size_t matchable = 0;      ///< visible, and within the parallax and footprint gates
  double overlap = 0.0;      ///< matchable / points (0 without points)
  /// The parallax of the nearer points: the 90th percentile over the visible points of the angle
  /// at the point between the rays to the two camera centres [deg]
  double parallax_deg = 0.0;
};

/// What a frame at `pose` with `intrinsics` sees of `points` observed from `reference` (focal
/// length `reference_focal` = sqrt(fx fy)). The gates are the matrix's (METHOD.md version 2):
/// parallax at most `max_parallax_deg` and footprint ratio within `max_scale_ratio` (0: off).
/// No occlusion test (it has a tolerance in metres, and the frame's depth is not read yet).
/// Angles and ratios only: scaling the world changes nothing. O(points).
ViewChange measureViewChange(const Eigen::Matrix3Xd& points, const Eigen::Vector3d& reference,
                             double reference_focal, const CameraPose& pose,
                             const PinholeIntrinsics& intrinsics, double max_parallax_deg,
                             double max_scale_ratio);

/// A reference with fewer points cannot be measured against: the frame is taken.
inline constexpr int kMinReferencePoints = 8;
/// [s] scale_free before any keyframe has points (a feature or map source starting): a new
/// keyframe once the optical axis turned keyframe_parallax_deg or this long after the last one
/// (a time, not a distance: no unit of the world enters), so the start of a video does not make
/// every frame a keyframe while the first points cannot be triangulated yet.
inline constexpr double kNoPointsInterval = 0.5;
/// The gate the overlap counts with: the matchable gate's default limits, fixed, so that the
/// keyframes do not change when the matrix's gate is tuned (gate: paper included).
inline constexpr double kOverlapMaxParallaxDeg = 20.0;
inline constexpr double kOverlapMaxScaleRatio = 1.6;

/// What the scale_free policy compares a frame with: the last keyframe as it is now (its points
/// may have grown since it was inserted) and the gate its overlap counts with.
struct KeyframeReference {
  CameraPose pose;
  PinholeIntrinsics intrinsics;
  /// The last keyframe's points (not owned); when it has fewer than kMinReferencePoints, a
  /// plane at the scene depth of a keyframe that has them (ViewSelector::keyframeReference).
  const Eigen::Matrix3Xd* points = nullptr;  ///< null: no keyframe has points yet
  Eigen::Matrix3Xd plane;  ///< storage for that plane
  double stamp = 0.0;      ///< the last keyframe's stamp [s]
  double max_parallax_deg = kOverlapMaxParallaxDeg;
  double max_scale_ratio = kOverlapMaxScaleRatio;
};


/// The policy's rule in words, with units, for log lines and summaries.
std::string describeKeyframeRule(const KeyframePolicyConfig& config);

class KeyframePolicy {
 public:
  explicit KeyframePolicy(KeyframePolicyConfig config = {});

  /// Offers the next frame; true when it should become a keyframe. Counts the frame either way.
  /// The policy remembers the pose only once the caller confirms with keyframeAccepted(), so a
  /// frame that is dropped later (no points, bad depth) does not move the reference.
  /// `external`: the verdict in kExternal mode (ignored otherwise). `reference`: what kScaleFree
  /// compares with (null: no keyframe yet, or nothing to measure against: the frame is taken);
  /// `intrinsics`: the frame's, for kScaleFree.
  /// `stamp`: the frame's [s] (kScaleFree before any keyframe has points; NaN: unknown).
  bool offer(const CameraPose& pose, bool external = false,
             const KeyframeReference* reference = nullptr, const PinholeIntrinsics* intrinsics = nullptr,
             double stamp = std::numeric_limits<double>::quiet_NaN());
  /// Whether this mode needs a KeyframeReference (the keyframes' points) to decide.
  bool needsReference() const { return config_.mode == KeyframeMode::kScaleFree; }
  /// kScaleFree's revisit rule: whether `reference` (an earlier keyframe near the frame) already
  /// has the view of a frame at `pose`: the frame sees at least keyframe_overlap of its points
  /// (at least one) within the gates and the parallax stays under keyframe_parallax_deg, the
  /// measure offer() takes against the last keyframe. A reference without kMinReferencePoints
  /// points covers nothing.
  bool covers(const KeyframeReference& reference, const CameraPose& pose,
              const PinholeIntrinsics& intrinsics) const;
  /// The last decision's measure (kScaleFree; empty before one was measured).
  const std::optional<ViewChange>& lastChange() const { return last_change_; }
  /// The frame offered last did become a keyframe at `pose`.
  void keyframeAccepted(const CameraPose& pose);
  void reset();
  /// New thresholds from the next frame on; the last keyframe and the frame count stay.
  void setConfig(const KeyframePolicyConfig& config) {
    config.validate();
    config_ = config;
  }
  const KeyframePolicyConfig& config() const { return config_; }

  /// Where the policy is: what a saved session needs to continue exactly. kScaleFree keeps no
  /// state of its own: it measures against the keyframes, which the session saves.
  struct State {
    long frames_offered = 0;                  ///< frames offered so far (every_nth counts them)
    std::optional<CameraPose> last_keyframe;  ///< motion: the reference pose
  };
  State state() const { return {frames_offered_, last_keyframe_}; }
  /// Continues from `state` (throws InvalidInput for a negative count or an invalid pose).
  void restore(const State& state);

 private:
  /// kScaleFree: whether `change` is a new view (under keyframe_overlap, or the parallax
  /// reached keyframe_parallax_deg).
  bool isNewView(const ViewChange& change) const;

  KeyframePolicyConfig config_;
  long frames_offered_ = 0;
  std::optional<CameraPose> last_keyframe_;
  std::optional<ViewChange> last_change_;
};

}  // namespace view_selection::core
