// The whole online method in one ROS-free class: frames in, keyframes kept, the error-resistance
// matrix updated incrementally, the selection computed on demand. The node and select_views both
// drive this class, which is why they give the same answer for the same frames.
#pragma once

#include "view_selection/core/depth_sampler.h"
#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/keyframe_policy.h"
#include "view_selection/core/point_source.h"
#include "view_selection/core/selection.h"

#include <nlohmann/json.hpp>

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace view_selection {

struct ViewSelectorConfig {
  KeyframePolicyConfig keyframes;
  DepthSamplerConfig depth;          ///< sampling grid and the occlusion depth map
  ErrorResistanceConfig matrix;
  SelectionConfig selection;
  bool occlusion_test = true;        ///< keep a downsampled depth map per keyframe when depth exists

  void validate() const;
};

enum class FrameOutcome {
  kKeyframe,         ///< became keyframe `id`
  kSkippedByPolicy,  ///< valid, but the keyframe policy did not want it
};

struct FrameResult {
  FrameOutcome outcome = FrameOutcome::kSkippedByPolicy;
  ViewId id = -1;                     ///< keyframe id when outcome == kKeyframe
  size_t points = 0;                  ///< sample points of the new keyframe
  std::vector<ViewId> updated_rows;   ///< earlier keyframes whose rows were recomputed
  double points_seconds = 0.0;        ///< time in the point source
  double matrix_seconds = 0.0;        ///< time inserting into the matrix (row, column, updates)
};

class ViewSelector {
 public:
  /// Takes ownership of the point source; a DepthPointSource when null.
  explicit ViewSelector(ViewSelectorConfig config, std::unique_ptr<PointSource> points = nullptr);

  /// Validates the frame (throws InvalidInput with a reason; nothing changes then), rejects a
  /// stamp not after the previous frame's (duplicate or out of order), applies the keyframe
  /// policy, gets the points and inserts the keyframe.
  FrameResult addFrame(const Frame& frame);
  /// Whether the keyframe policy would take a frame at `pose` next, without changing anything.
  /// Lets callers skip loading depth and images for frames that will not become keyframes
  /// (they still pass those frames to addFrame, without depth, to keep counts and stamps).
  bool wantsFrame(const CameraPose& pose) const;
  /// The selection for the keyframes so far.
  Selection select() const;
  void reset();

  const ErrorResistanceMatrix& matrix() const { return matrix_; }
  const ViewSelectorConfig& config() const { return config_; }
  const PointSource& pointSource() const { return *points_; }
  /// For sources fed from outside (MapPointSource::setMapPoints); call applyPointUpdates after.
  PointSource& pointSource() { return *points_; }
  /// Applies the point source's pending changes to earlier keyframes (PointSource::takeUpdates):
  /// recomputes exactly those rows and returns their ids. Throws InvalidInput for an update of
  /// an unknown keyframe or with non-finite points; nothing changes then.
  std::vector<ViewId> applyPointUpdates();
  /// Every parameter that shapes the result, as written to selection.json's "params".
  nlohmann::json params() const;

 private:
  FrameResult insert(const Frame& frame, const CameraPose& pose);

  ViewSelectorConfig config_;
  std::unique_ptr<PointSource> points_;
  KeyframePolicy policy_;
  ErrorResistanceMatrix matrix_;
  std::optional<double> last_stamp_;  // of the last valid frame offered
};

/// Throws InvalidInput when a frame cannot be used (intrinsics, pose, depth type or size).
void validateFrame(const Frame& frame);

}  // namespace view_selection
