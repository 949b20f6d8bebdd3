// The whole online method in one ROS-free class: frames in, keyframes kept, the error-resistance
// matrix updated incrementally, the selection computed on demand. The node and select_views both
// drive this class, which is why they give the same answer for the same frames.
#pragma once

#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/frame.h"
#include "view_selection/core/frame_registration.h"
#include "view_selection/core/keyframe_neighbours.h"
#include "view_selection/core/keyframe_policy.h"
#include "view_selection/core/pair_buckets.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/point_source.h"
#include "view_selection/core/selection.h"
#include "view_selection/core/selection_cache.h"
#include "view_selection/core/selection_output.h"

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace view_selection::core {

/// Every parameter of the method (the point sources have their own, in points/).
struct ViewSelectorConfig {
  KeyframePolicyConfig keyframes;
  ErrorResistanceConfig matrix;  ///< gates; matrix.occlusion: the depth map kept per keyframe
  SelectionConfig selection;

  void visitParameters(ParameterVisitor& v);
  void validate() const { checkRanges(*this); }
};

enum class FrameOutcome {
  kKeyframe,         ///< became keyframe `id`
  kSkippedByPolicy,  ///< valid, but the keyframe policy did not want it
};

struct FrameResult {
  FrameOutcome outcome = FrameOutcome::kSkippedByPolicy;
  ViewId id = -1;                    ///< keyframe id when outcome == kKeyframe
  /// kSkippedByPolicy by the revisit rule: the earlier keyframe that already has the view
  /// (-1: not skipped, or the last keyframe had it)
  ViewId covered_by = -1;
  /// ... found by registering the frame's image (registeredCoveringKeyframe), not by its pose
  bool covered_by_registration = false;
  size_t points = 0;                 ///< sample points of the new keyframe
  std::vector<ViewId> updated_rows;  ///< earlier keyframes whose rows were recomputed
  double points_seconds = 0.0;       ///< time in the point source
  double matrix_seconds = 0.0;       ///< time inserting into the matrix (row, column, updates)
};

/// Everything of a ViewSelector but its point source, for saving a session and continuing it
/// exactly (io/state_file saves it with the point source's own state).
struct ViewSelectorState {
  ViewSelectorConfig config;
  std::vector<Keyframe> keyframes;            ///< by id, with points and occlusion depth maps
  std::vector<std::vector<TableEntry>> rows;  ///< E's finite entries, row by row
  KeyframePolicy::State policy;
  std::optional<double> last_stamp;  ///< of the last valid frame offered
};

class ViewSelector {
 public:
  /// Takes ownership of the point source (points::makePointSource makes one by name). Throws
  /// InvalidArgument for a null source or a parameter out of range.
  ViewSelector(ViewSelectorConfig config, std::unique_ptr<PointSource> points);

  /// Validates the frame (throws InvalidInput with a reason; nothing changes then), rejects a
  /// stamp not after the previous frame's (duplicate or out of order), applies the keyframe
  /// policy, gets the points and inserts the keyframe.
  FrameResult addFrame(const Frame& frame);
  /// Whether the keyframe policy would take `frame` next, without changing anything; it reads
  /// the frame's stamp-free parts only (pose, intrinsics, external_keyframe), not its images.
  /// Lets callers skip loading depth and images for frames that will not become keyframes
  /// (they still pass those frames to addFrame, without depth, to keep counts and stamps).
  bool wantsFrame(const Frame& frame) const;
  /// What the scale_free policy compares the next frame with: the last keyframe, with its points
  /// as they are now; when it has fewer than kMinReferencePoints, a plane across its image at
  /// the median depth of the latest of the kReferenceLookBack keyframes before it that has
  /// them; null without a keyframe or without any such depth. O(points), not O(keyframes).
  const KeyframeReference* keyframeReference() const;
  static constexpr int kReferenceLookBack = 64;
  /// The scale_free policy's revisit rule: a frame whose view has changed against the last
  /// keyframe still becomes none when an earlier keyframe near it already has its view
  /// (KeyframePolicy::covers: the same measure). The earlier keyframe that does, or -1; looks at
  /// the kRevisitCandidates most alike of those that can (KeyframeNeighbours::query).
  /// Measured on the built-in walk round one room (docs/design.md, "Revisits").
  ViewId coveringKeyframe(const CameraPose& pose, const PinholeIntrinsics& intrinsics) const;
  static constexpr size_t kRevisitCandidates = 8;
  /// The revisit rule under drift (keyframe_policy's revisit_registration, with a registration
  /// set): when coveringKeyframe finds none, `frame` is registered from its image to keyframes
  /// made at least kRecentSeconds before it (the poses judge the others: little drift lies
  /// between them and the frame). The candidates are the kRegisteredCandidates most alike by pose
  /// where the last registration placed the frame before, by the images
  /// (FrameRegistration::alikeKeyframes) and by the frame's own pose. Where it registers, the
  /// frame is measured again (KeyframePolicy::covers) at the registered pose (the keyframe's
  /// pose composed with the frame's relative to it) against that keyframe and the
  /// kRegisteredWindow made before and after it, which share its drift. The keyframe that
  /// covers it there, or -1. docs/design.md, "Revisits under drift".
  ViewId registeredCoveringKeyframe(const Frame& frame, const CameraPose& pose);
  static constexpr size_t kRegisteredCandidates = 3;
  static constexpr double kRecentSeconds = 2.0;
  static constexpr ViewId kRegisteredWindow = 16;
  /// Measures frames against earlier keyframes from their images (for
  /// registeredCoveringKeyframe); null: the poses alone. Keyframes made before it was set are
  /// never registered to; reset() and restore() clear it.
  void setRegistration(std::unique_ptr<FrameRegistration> registration);
  /// Frames the revisit rule kept from becoming keyframes so far (since reset()), and of them
  /// those recognised by registration (registeredCoveringKeyframe).
  size_t revisitsSkipped() const { return revisits_skipped_; }
  size_t revisitsRegistered() const { return revisits_registered_; }
  /// The selection for the keyframes so far (selectViews, kept current incrementally), as a
  /// plain Selection (O(n): for tools and tests; outputs take output()).
  Selection select() const;
  /// The keyframes, E, the selection and params() together, for outputs: shares every chunk
  /// with the selector's own lists, so it costs O(n / 256) plus the selection's update.
  SelectionOutput output() const;
  /// With tracking on, the pairs of the selection that appeared and went are kept between
  /// takePairChanges() calls (SelectionCache::trackPairChanges); off by default.
  void trackPairChanges(bool on) { selection_.trackPairChanges(on); }
  /// The pairs that appeared and went since the last call (as of the last select()/output()).
  PairChanges takePairChanges() { return selection_.takePairChanges(); }
  void reset();
  /// The whole state but the point source's (copies the keyframes; depth maps are shared).
  ViewSelectorState state() const;
  /// The policy's and the last stamp's part of state(), without copying keyframes.
  KeyframePolicy::State policyState() const { return policy_.state(); }
  std::optional<double> lastStamp() const { return last_stamp_; }
  /// Continues from a saved state, with its config: keyframes and E as saved (no entry
  /// recomputed), the policy and the last stamp. The point source is the caller's to restore.
  /// Throws InvalidArgument / InvalidInput (nothing changes then).
  void restore(const ViewSelectorState& state);
  /// New parameters for what comes next (throws InvalidArgument; nothing changes then): the
  /// keyframe policy keeps its place, the matrix is recomputed only when its parameters differ,
  /// the selection follows. Keyframes and their points stay.
  void setConfig(const ViewSelectorConfig& config);

  const ErrorResistanceMatrix& matrix() const { return matrix_; }
  const ViewSelectorConfig& config() const { return config_; }
  const PointSource& pointSource() const { return *points_; }
  /// For sources fed from outside (MapPointSource::setMapPoints); call applyPointUpdates after.
  PointSource& pointSource() { return *points_; }
  /// Applies the point source's pending changes to earlier keyframes (PointSource::takeUpdates):
  /// recomputes exactly those rows and returns their ids. Throws InvalidInput for an update of
  /// an unknown keyframe or with non-finite points; nothing changes then.
  std::vector<ViewId> applyPointUpdates();
  /// New poses for keyframes (loop closure; see ErrorResistanceMatrix::setPoses, whose
  /// exceptions it passes on). When the last keyframe moves, the keyframe policy measures motion
  /// from its new pose.
  void correctPoses(const std::vector<std::pair<ViewId, CameraPose>>& poses);
  /// Every parameter that shapes the result, as written to selection.json's "params": the
  /// method's, then "point_source" and the group "point_source_params".
  Params params() const;

 private:
  FrameResult insert(const Frame& frame, const CameraPose& pose);
  /// Whether keyframe `id` has the view of a frame at `pose` (KeyframePolicy::covers with the
  /// last keyframe's fixed gates).
  bool keyframeCovers(ViewId id, const CameraPose& pose, const PinholeIntrinsics& intrinsics) const;
  /// Whether frames are registered (a registration set, revisit_registration, scale_free).
  bool registers() const;
  /// Whether the revisit rule applies to the policy's last verdict (scale_free, measured).
  bool revisitRuleApplies(const KeyframePolicy& policy) const;
  /// The revisit rule's index from the keyframes as they are (restore, a new keyframe_overlap).
  void indexNeighbours();

  ViewSelectorConfig config_;
  std::unique_ptr<PointSource> points_;
  KeyframePolicy policy_;
  ErrorResistanceMatrix matrix_;
  std::optional<double> last_stamp_;  // of the last valid frame offered
  mutable KeyframeReference reference_;  // keyframeReference()'s, rebuilt on each call
  // The keyframes by centre for the revisit rule; its searches regrid, hence mutable.
  mutable KeyframeNeighbours neighbours_;
  mutable std::vector<ViewId> near_;  // coveringKeyframe()'s, reused
  size_t revisits_skipped_ = 0;
  size_t revisits_registered_ = 0;
  // World to world: where the last registration placed a frame against its pose
  std::optional<CameraPose> revisit_offset_;
  // The keyframe that registration found to cover the last frame the revisit rule measured, or
  // -1 (the poses covered it, or a keyframe was made since): the next keyframe's revisit_of.
  ViewId revisit_link_ = -1;
  std::unique_ptr<FrameRegistration> registration_;
  // What select() last returned, updated from the rows that changed since. Not shared between
  // threads: like every other member, one thread at a time drives a ViewSelector.
  mutable SelectionCache selection_;
  mutable std::shared_ptr<const Params> params_;  // params(), made once per configuration
};

}  // namespace view_selection::core
