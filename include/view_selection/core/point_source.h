// Where a keyframe's sample points X_i come from: depth back-projection here; feature
// triangulation and external map points implement the same interface.
#pragma once

#include "view_selection/core/depth_sampler.h"
#include "view_selection/core/types.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace view_selection {

/// One incoming frame, already converted from files or messages.
struct Frame {
  double stamp = 0.0;             ///< [s]
  std::string image_name;         ///< name used in pairs.txt
  PinholeIntrinsics intrinsics;
  CameraPose pose;                ///< camera-to-world, optical frame
  cv::Mat depth_m;                ///< CV_32FC1 metres (0 = invalid), or empty when no depth
  cv::Mat image;                  ///< colour (BGR) or grey; may be empty for depth-only sources
};

struct PointSourceResult {
  Eigen::Matrix3Xd points;  ///< X_n of the new keyframe, world coordinates
  /// Earlier keyframes whose point sets changed (e.g. new tracks reached them): their full new
  /// point sets. The matrix recomputes exactly these rows.
  std::vector<std::pair<ViewId, Eigen::Matrix3Xd>> updated;
};

class PointSource {
 public:
  virtual ~PointSource() = default;
  /// "depth", "features", "map".
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
  virtual nlohmann::json params() const { return nlohmann::json::object(); }
};

/// Points back-projected from the frame's depth image (one per grid cell).
class DepthPointSource : public PointSource {
 public:
  explicit DepthPointSource(DepthSamplerConfig config = {});
  std::string name() const override { return "depth"; }
  PointSourceResult process(ViewId id, const Frame& frame) override;
  void reset() override {}
  nlohmann::json params() const override;

 private:
  DepthSamplerConfig config_;
};

}  // namespace view_selection
