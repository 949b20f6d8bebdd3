// Camera and keyframe types shared by every part of the core. No ROS in here.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <memory>
#include <string>
#include <vector>

namespace view_selection::core {

/// Keyframe index: 0-based, in arrival order.
using ViewId = int;

/// Pinhole intrinsics in pixels. The image spans [0, width) x [0, height).
struct PinholeIntrinsics {
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  int width = 0;
  int height = 0;

  /// True when focal lengths are positive and finite and the size is positive.
  bool isValid() const;

  /// Pixel of a point in camera coordinates (z > 0 assumed by the caller).
  Eigen::Vector2d project(const Eigen::Vector3d& p_cam) const {
    return {fx * p_cam.x() / p_cam.z() + cx, fy * p_cam.y() / p_cam.z() + cy};
  }
  /// Ray through a pixel, in camera coordinates, with z = 1.
  Eigen::Vector3d backProject(const Eigen::Vector2d& px) const {
    return {(px.x() - cx) / fx, (px.y() - cy) / fy, 1.0};
  }
  bool inImage(const Eigen::Vector2d& px) const {
    return px.x() >= 0.0 && px.y() >= 0.0 && px.x() < width && px.y() < height;
  }
  Eigen::Matrix3d matrix() const;
};

/// Camera pose, camera-to-world, optical frame (z forward, x right, y down).
struct CameraPose {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();               ///< camera centre O [m]
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< camera-to-world

  /// True when every component is finite and the quaternion has a usable norm.
  bool isValid() const;

  Eigen::Matrix3d rotation() const { return orientation.normalized().toRotationMatrix(); }
  /// World point to camera coordinates.
  Eigen::Vector3d worldToCamera(const Eigen::Vector3d& p_world) const {
    return rotation().transpose() * (p_world - position);
  }
  /// Unit optical axis in world coordinates.
  Eigen::Vector3d opticalAxis() const { return rotation().col(2); }
};

/// Depth map kept by a keyframe for the occlusion test, downsampled from the full image.
/// Cell (c, r) covers full-resolution pixels [c*cell_w, (c+1)*cell_w) x [r*cell_h, ...).
/// A value of 0 means "no valid depth in that cell": the occlusion test cannot tell and passes.
struct DepthMap {
  int cols = 0;
  int rows = 0;
  double cell_width = 1.0;   ///< full-resolution pixels per cell, horizontally
  double cell_height = 1.0;  ///< full-resolution pixels per cell, vertically
  std::vector<float> depth;  ///< row-major, metres, 0 = unknown

  bool empty() const { return depth.empty(); }
  /// Sizes agree (depth holds cols x rows values), cells are positive, depths finite and >= 0.
  bool isConsistent() const;
  /// Depth [m] at a full-resolution pixel, 0 when unknown or outside (or NaN).
  float at(double u, double v) const {
    // Multiplying by the inverse is exact for the power-of-two cells used in practice and this
    // lookup is the inner loop of the matrix; for other sizes a pixel on a cell border may
    // fall into its neighbour, which the occlusion tolerance absorbs.
    const double c = u * (1.0 / cell_width);
    const double r = v * (1.0 / cell_height);
    // Bounds checked before the conversion to int, which no value may overflow (a state file's
    // tiny cell, fuzz/regressions/state_file).
    if (!(c >= 0.0 && r >= 0.0 && c < cols && r < rows)) return 0.0f;
    return depth[static_cast<size_t>(static_cast<int>(r)) * cols + static_cast<int>(c)];
  }
};

/// One keyframe: where the camera was, how it images, and what it observed.
struct Keyframe {
  double stamp = 0.0;      ///< seconds
  std::string image_name;  ///< image path relative to the image folder given to COLMAP
  PinholeIntrinsics intrinsics;
  CameraPose pose;
  Eigen::Matrix3Xd points;                ///< sample points X_i, world coordinates [scene units]
  std::shared_ptr<const DepthMap> depth;  ///< optional, for the occlusion test in this view
  /// The earlier keyframe that the frames just before this one were recognised from their
  /// images to revisit (ViewSelector's revisit rule under drift), or -1: a pair across drift
  /// that the poses do not show, for a consumer to match without trusting the poses.
  ViewId revisit_of = -1;
};

}  // namespace view_selection::core
