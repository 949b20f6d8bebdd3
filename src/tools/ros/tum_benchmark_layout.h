// tum_to_bag --layout tum: a TUM folder written as the TUM RGB-D benchmark's own bags are laid
// out (rgbd_dataset_freiburg1_xyz.bag and the others), not only with their topic names:
//  - /tf of type tf/tfMessage, no /tf_static, every frame id with a leading '/';
//  - the chain /world -> /kinect (motion capture at ~100 Hz, from the ground truth, starting
//    seconds before the first image) -> /openni_camera -> /openni_rgb_frame ->
//    /openni_rgb_optical_frame, the fixed links re-sent on /tf as the old
//    static_transform_publisher did, stamped ahead by its period;
//  - depth stamps ~15 ms off the colour stamps, bag time a little after each stamp (recording
//    latency), stamps ~1.3e9 s.
#pragma once

#include "bag_messages.h"

#include "view_selection/core/types.h"
#include "view_selection/io/tum_dataset.h"

#include <rosbag/bag.h>

#include <string>
#include <vector>

namespace view_selection::tum_to_bag {

struct BenchmarkLayoutOptions {
  long long stamp_offset = 0;    ///< [s] added to every stamp (whole seconds)
  double depth_offset = -0.015;  ///< [s] depth stamp minus colour stamp ...
  double depth_jitter = 0.002;   ///< [s] ... plus a deterministic jitter within +-this
  double mocap_rate = 100.0;     ///< [Hz] /world -> /kinect
  double mocap_lead = 3.0;       ///< [s] motion capture starts this long before the first image
  double static_period = 0.1;    ///< [s] fixed links re-sent this often, stamped this far ahead
  double image_latency = 0.02;   ///< [s] bag time of an image minus its stamp
  std::string world_frame = "/world";
  std::string camera_frame = "/openni_rgb_optical_frame";
  /// Also the motion capture as the topics SLAM systems publish (not in the benchmark's bags):
  /// /mocap/pose (PoseStamped), /mocap/odometry (Odometry, child /kinect) and
  /// /mocap/pose_with_covariance, all of /kinect in the world frame.
  bool pose_topics = false;
  ImageTopics images;  ///< raw or compressed colour and depth
  bool quiet = false;
};

/// The fixed links of the benchmark's chain, parent -> child, in order from /kinect to the
/// optical frame (the last child is options.camera_frame).
struct FixedLink {
  std::string parent, child;
  core::CameraPose transform;  ///< child-to-parent
};
std::vector<FixedLink> benchmarkFixedLinks(const std::string& camera_frame);

struct WrittenFrames {
  size_t frames = 0;
  double first = 0.0, last = 0.0;  ///< colour stamps as written [s]
};

/// Writes `frames` (indices into dataset.frames, ascending) into `bag`. The ground truth comes
/// from the folder's groundtruth.txt (every line, interpolated to the motion-capture rate).
/// Throws core::IoError / core::InvalidInput with a message.
WrittenFrames writeBenchmarkLayout(rosbag::Bag& bag, const io::TumDataset& dataset,
                                   const std::vector<size_t>& frames,
                                   const BenchmarkLayoutOptions& options);

}  // namespace view_selection::tum_to_bag
