// Where a keyframe's sample points X_i come from: the interface. Depth back-projection, feature
// triangulation and external map points implement it in points/.
#pragma once

#include "view_selection/core/frame.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <string>
#include <utility>
#include <vector>

namespace view_selection::core {

struct PointSourceResult {
  Eigen::Matrix3Xd points;  ///< X_n of the new keyframe, world coordinates
  /// Earlier keyframes whose point sets changed (e.g. new tracks reached them): their full new
  /// point sets. The matrix recomputes exactly these rows.
  std::vector<std::pair<ViewId, Eigen::Matrix3Xd>> updated;
};

class PointSource {
 public:
  virtual ~PointSource() = default;
  /// "depth", "features", "map", "auto".
  virtual std::string name() const = 0;
  /// Called once for each new keyframe, which will get id `id`, before it enters the matrix.
  /// Throws InvalidInput when the frame lacks what the source needs (e.g. depth).
  virtual PointSourceResult process(ViewId id, const Frame& frame) = 0;
  /// Forgets everything.
  virtual void reset() = 0;
  /// Point-set changes of earlier keyframes made outside process() (e.g. new map points) since
  /// the last call, as full new point sets; the ViewSelector recomputes exactly these rows
  /// (ViewSelector::applyPointUpdates). Sources whose sets change only in process(): none.
  virtual std::vector<std::pair<ViewId, Eigen::Matrix3Xd>> takeUpdates() { return {}; }
  /// The parameters that shape the points, for selection.json's "point_source_params".
  virtual Params params() const { return {}; }
};

}  // namespace view_selection::core
