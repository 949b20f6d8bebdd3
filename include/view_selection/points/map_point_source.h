// Sample points from outside: world points (e.g. a SLAM system's map points) assigned to each
// keyframe by visibility. New map points change the sets of earlier keyframes; those changes are
// reported through takeUpdates() (and with the next keyframe) so only their rows are recomputed.
#pragma once

#include "view_selection/core/occlusion_map.h"
#include "view_selection/core/point_source.h"

#include <memory>
#include <optional>
#include <vector>

namespace view_selection::points {

struct MapPointSourceConfig {
  /// Points farther along the optical axis are not assigned; 0: no limit [scene units].
  double max_depth = 0.0;
  int max_points = 2000;  ///< per keyframe, evenly thinned by index beyond this; 0: all
  /// Drops points the keyframe's depth (when it has one) contradicts. Not a parameter of its
  /// own: makePointSource copies the matrix's occlusion settings, so both tests agree.
  core::OcclusionConfig occlusion;

  void visitParameters(core::ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const {
    core::checkRanges(*this);
    occlusion.validate();
  }
};

/// The points of `points` that a camera sees: in front (z > 0, and z <= max_depth when set),
/// projecting inside the image, and (with a depth map) not contradicted by it. Then thinned to
/// config.max_points. Column order follows `points`.
Eigen::Matrix3Xd visibleMapPoints(const Eigen::Matrix3Xd& points,
                                  const core::PinholeIntrinsics& intrinsics,
                                  const core::CameraPose& pose, const core::DepthMap* depth,
                                  const MapPointSourceConfig& config);

class MapPointSource : public core::PointSource {
 public:
  explicit MapPointSource(MapPointSourceConfig config = {});
  std::string name() const override { return "map"; }
  /// Assigns the current map points visible to the keyframe (none before the first map), and
  /// carries the pending updates of earlier keyframes.
  core::PointSourceResult process(core::ViewId id, const core::Frame& frame) override;
  void reset() override;
  std::vector<std::pair<core::ViewId, Eigen::Matrix3Xd>> takeUpdates() override;
  core::Params params() const override { return core::paramsOf(config_); }

  /// Replaces the map (throws InvalidInput for non-finite points; nothing changes then) and
  /// reassigns the keyframes; keyframes whose set changed become pending updates. Incremental:
  /// when the points the two maps share keep their order (a SLAM map that grows, moves or
  /// drops some points), only the keyframes that see a point that came or went are projected
  /// against the new map (the others' assignments are what a full reassignment gives); else
  /// every keyframe is.
  void setMapPoints(Eigen::Matrix3Xd points);
  /// Keyframes projected against the map by the last setMapPoints (for tests and benchmarks).
  size_t lastReassigned() const { return reassigned_; }
  const Eigen::Matrix3Xd& mapPoints() const { return map_; }
  /// Keyframes whose updates are pending (ascending).
  std::vector<core::ViewId> pendingUpdates() const;

  /// What a keyframe holds in this source.
  struct View {
    core::ViewId id = -1;
    core::PinholeIntrinsics intrinsics;
    core::CameraPose pose;
    std::shared_ptr<const core::DepthMap> depth;  ///< its occlusion map, or null
    Eigen::Matrix3Xd assigned;                    ///< the map points it sees
    bool pending = false;                         ///< assigned changed, not yet taken
  };
  /// Everything this source keeps, for saving a session and continuing it exactly.
  struct State {
    Eigen::Matrix3Xd map = Eigen::Matrix3Xd(3, 0);
    std::vector<View> views;  ///< ascending id
  };
  State state() const { return {map_, views_}; }
  /// Throws InvalidInput (nothing changes then) for non-finite points, ids that do not ascend,
  /// invalid intrinsics or poses, or an inconsistent depth map.
  void restore(State state);

 private:
  MapPointSourceConfig config_;
  Eigen::Matrix3Xd map_ = Eigen::Matrix3Xd(3, 0);
  std::vector<View> views_;
  size_t reassigned_ = 0;
};

/// The points that came (columns of `after` matched by no point of `before`) and went (of
/// `before` matched by none of `after`), matched by their exact coordinates; nullopt when the
/// points the two share are not in the same relative order.
std::optional<Eigen::Matrix3Xd> changedMapPoints(const Eigen::Matrix3Xd& before,
                                                 const Eigen::Matrix3Xd& after);

}  // namespace view_selection::points
