// The poses corrected from the matches alone (issue 34, "a refined model at every length"): before
// the bundle adjustment, every keyframe pose is adjusted so that each verified pair's matches lie
// on their epipolar lines, with the SLAM's relative motion between consecutive keyframes holding
// the scale and what the matches do not connect. It has no points: its size is the keyframes' and
// a bounded number of matches a pair, so it converges in about a second where one
// bundle-adjustment iteration of a long session takes as long. A revisit's pairs disagree with the
// drifted poses along the whole epipolar geometry; this stage spreads their correction along the
// loop (as a SLAM system's pose graph does), and the bundle adjustment then starts close to its
// minimum.
#pragma once

#include "view_selection/refine/tracks.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <functional>
#include <vector>

namespace view_selection::refine {

/// A pair of images' matches as normalised rays K^-1 (x, y, 1), with each image's focal lengths
/// (the residuals are in pixels).
struct EpipolarPair {
  int a = 0, b = 0;  ///< image ids, a < b
  std::vector<Eigen::Vector3d> rays_a, rays_b;
  Eigen::Vector2d focal_a = Eigen::Vector2d::Ones(), focal_b = Eigen::Vector2d::Ones();
};

/// The pairs of images with at least `min_matches` matches, each with at most `per_pair` of them
/// (evenly spread over the pair's matches in their order). `pixel(image, index)` is a 2D point
/// (non-finite: the match is left out), `intrinsics(image)` fx, fy, cx, cy; matches of images
/// that `known(image)` denies are left out.
std::vector<EpipolarPair> epipolarPairs(const std::vector<Match>& matches, size_t per_pair, size_t min_matches,
                                        const std::function<bool(int)>& known,
                                        const std::function<Eigen::Vector2d(int, int)>& pixel,
                                        const std::function<Eigen::Vector4d(int)>& intrinsics);

/// The Sampson distances [px] of a pair's matches to the epipolar geometry of two poses, signed:
/// each the first-order distance of the match from the nearest pair of points that satisfies
/// x_b^T F x_a = 0. Poses as the refinement keeps them: Eigen's quaternion (x, y, z, w) then the
/// translation, world to camera. Free of the baseline's length; a baseline of zero gives 0.
/// One residual a match (Ceres: a dynamic number of residuals, the pair's rotation computed once).
struct EpipolarErrors {
  explicit EpipolarErrors(const EpipolarPair& pair) : pair(pair) {}

  template <typename T>
  bool operator()(const T* pose_a, const T* pose_b, T* residuals) const {
    using Vec3 = Eigen::Matrix<T, 3, 1>;
    const Eigen::Map<const Eigen::Quaternion<T>> ra(pose_a), rb(pose_b);
    const Eigen::Map<const Vec3> ta(pose_a + 4), tb(pose_b + 4);
    const Eigen::Matrix<T, 3, 3> r = (rb * ra.conjugate()).toRotationMatrix();  // a -> b
    const Vec3 t = tb - r * ta;  // E = [t]x R
    const T fxa(pair.focal_a.x()), fya(pair.focal_a.y()), fxb(pair.focal_b.x()), fyb(pair.focal_b.y());
    for (size_t q = 0; q < pair.rays_a.size(); ++q) {
      const Vec3 a = pair.rays_a[q].cast<T>(), b = pair.rays_b[q].cast<T>();
      const Vec3 ea = t.cross(r * a);                 // E a: the epipolar line in b
      const Vec3 etb = r.transpose() * b.cross(t);  // E^T b: the epipolar line in a
      const T denominator = ea.x() * ea.x() / (fxb * fxb) + ea.y() * ea.y() / (fyb * fyb) +
                            etb.x() * etb.x() / (fxa * fxa) + etb.y() * etb.y() / (fya * fya);
      residuals[q] = b.dot(ea) / sqrt(denominator + T(1e-300));
    }
    return true;
  }

  EpipolarPair pair;
};

}  // namespace view_selection::refine
