// Sample points from outside: world points (e.g. a SLAM system's map points) assigned to each
// keyframe by visibility. New map points change the sets of earlier keyframes; those changes are
// reported through takeUpdates() (and with the next keyframe) so only their rows are recomputed.
#pragma once

#include "view_selection/core/point_source.h"

#include <vector>

namespace view_selection {

struct MapPointSourceConfig {
  /// Points farther along the optical axis are not assigned; <= 0: no limit [scene units].
  double max_depth = 0.0;
  int max_points = 2000;       ///< per keyframe, evenly thinned by index beyond this; 0: all
  bool occlusion_test = true;  ///< drop points the keyframe's depth (when it has one) contradicts
  double occlusion_abs_tolerance = 0.05;  ///< visible when |z - D(p)| <= max(abs, rel * z) [m]
  double occlusion_rel_tolerance = 0.03;
  int depth_map_cell = 8;  ///< occlusion depth map: one value per n x n pixels

  /// Throws InvalidArgument naming the first field out of range.
  void validate() const;
  nlohmann::json toJson() const;
};

/// The points of `points` that a camera sees: in front (z > 0, and z <= max_depth when set),
/// projecting inside the image, and (with a depth map) not contradicted by it. Then thinned to
/// config.max_points. Column order follows `points`.
Eigen::Matrix3Xd visibleMapPoints(const Eigen::Matrix3Xd& points,
                                  const PinholeIntrinsics& intrinsics, const CameraPose& pose,
                                  const DepthMap* depth, const MapPointSourceConfig& config);

class MapPointSource : public PointSource {
 public:
  explicit MapPointSource(MapPointSourceConfig config = {});
  std::string name() const override { return "map"; }
  /// Assigns the current map points visible to the keyframe (none before the first map), and
  /// carries the pending updates of earlier keyframes.
  PointSourceResult process(ViewId id, const Frame& frame) override;
  void reset() override;
  std::vector<std::pair<ViewId, Eigen::Matrix3Xd>> takeUpdates() override;
  nlohmann::json params() const override { return config_.toJson(); }

  /// Replaces the map (throws InvalidInput for non-finite points; nothing changes then) and
  /// reassigns every keyframe; keyframes whose set changed become pending updates.
  void setMapPoints(Eigen::Matrix3Xd points);
  const Eigen::Matrix3Xd& mapPoints() const { return map_; }
  /// Keyframes whose updates are pending (ascending).
  std::vector<ViewId> pendingUpdates() const;

 private:
  struct View {
    ViewId id = -1;
    PinholeIntrinsics intrinsics;
    CameraPose pose;
    std::shared_ptr<const DepthMap> depth;
    Eigen::Matrix3Xd assigned;
    bool pending = false;
  };
  MapPointSourceConfig config_;
  Eigen::Matrix3Xd map_ = Eigen::Matrix3Xd(3, 0);
  std::vector<View> views_;
};

}  // namespace view_selection
