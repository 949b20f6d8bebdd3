// A global start for the rotations (issue 34, a refinement at every length): the keyframes'
// orientations that agree best with the SLAM's relative rotations between consecutive keyframes
// and with the relative rotations the verified pairs' own two-view geometries give, whatever the
// orientations the SLAM reported.
//
// Why: an odometry's heading drifts without bound (140 degrees by the middle of a 30-minute
// walk). The epipolar stage and the bundle adjustment are local: from such poses they pull a
// revisit's keyframes together by breaking the chain of motion priors at a weakly observed
// keyframe (a broken prior costs less than a revisit's pairs far off), and blocks of keyframes
// stay metres off. Rotation averaging is global: every relative rotation is linear in the
// unknown rotation matrices (R_b = R_ba R_a), so the least-squares rotations are one sparse
// linear solve, projected onto the rotations, with no starting point to fall into a wrong
// minimum from (the chordal relaxation of Martinec and Pajdla, 2007). Outlying relative rotations
// (a pair verified with a wrong geometry) are discounted by reweighting (a Cauchy loss at each
// relative rotation's sigma).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <map>
#include <string>
#include <vector>

namespace view_selection::refine {

/// A relative rotation between two images' world-to-camera rotations: R_b = rotation_ba R_a
/// (COLMAP's two-view geometry of the pair (a, b): x_b = R x_a + t), with its sigma [rad].
struct RelativeRotation {
  int a = 0, b = 0;
  Eigen::Quaterniond rotation_ba = Eigen::Quaterniond::Identity();
  double sigma = 0.0;
};

struct RotationAveragingResult {
  std::map<int, Eigen::Quaterniond>
      rotations;        ///< every image of the start, averaged or as it came
  int iterations = 0;   ///< reweighted solves made
  bool solved = false;  ///< false: the linear solve failed, the start returned
};

/// The world-to-camera rotations of the images of `start` that agree best with `relatives`
/// (those naming an image `start` lacks are left out), with `held` kept at its start rotation
/// (the frame). At most `iterations` reweighted solves, fewer once no rotation changes by more
/// than 1e-3 degrees. An image that no relative rotation connects to `held` keeps its start
/// rotation (its group of images turns as one about it, held by a weak pull to their start).
RotationAveragingResult averageRotations(const std::map<int, Eigen::Quaterniond>& start,
                                         const std::vector<RelativeRotation>& relatives, int held,
                                         int iterations);

/// A pair's relative rotation as a file gives it (RelativeRotation without a sigma).
struct PairRotation {
  int a = 0, b = 0;
  Eigen::Quaterniond rotation_ba = Eigen::Quaterniond::Identity();
};

/// A pair rotations file: "VSROTAT1", a little-endian uint64 count, then count x (int32 image
/// id a, int32 image id b, float64 w, x, y, z of rotation_ba). Throws core::IoError naming the
/// file (also for a quaternion that is not of unit length, or a non-finite one).
std::vector<PairRotation> readPairRotations(const std::string& path);
void writePairRotations(const std::string& path, const std::vector<PairRotation>& rotations);

}  // namespace view_selection::refine
