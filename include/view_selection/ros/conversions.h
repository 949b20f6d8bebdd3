// Messages to core types and back. Every function that reads a message validates it and throws
// view_selection::InvalidInput with a message a user can act on; none of them copies pixels
// unless it has to.
#pragma once

#include "view_selection/core/image.h"
#include "view_selection/core/selection_output.h"
#include "view_selection/core/types.h"

#include <view_selection/ViewSelection.h>

#include <geometry_msgs/Pose.h>
#include <geometry_msgs/Transform.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace view_selection::ros_node {

/// Intrinsics from camera_info's K (fx = K[0], fy = K[4], cx = K[2], cy = K[5]) and its size.
/// Throws InvalidInput for a zero, negative or non-finite focal length or a zero size.
core::PinholeIntrinsics intrinsicsFromCameraInfo(const sensor_msgs::CameraInfo& info);

/// Checks an image message's shape before anything reads its pixels: non-zero size, a known
/// encoding, step >= width * pixel size and a whole number of channel elements, and data
/// holding step * height bytes. `what` names the input in the message ("image", "depth"); for
/// "image" the encoding must also be a colour, grey or Bayer one. Throws InvalidInput.
void checkImageMessage(const sensor_msgs::Image& msg, const std::string& what);

/// A cv::Mat header over the message's pixels (no copy), in the message's own encoding.
/// The message must outlive the Mat. Call checkImageMessage first (InvalidInput otherwise).
cv::Mat imageView(const sensor_msgs::Image& msg);

/// The image as the core wants it: BGR (8 bit) for colour encodings, grey for mono8.
/// Copies only when the encoding needs converting. Throws InvalidInput.
cv::Mat imageForCore(const sensor_msgs::ImageConstPtr& msg);
/// The same as a core image view that keeps the message (or the converted copy) alive.
core::ColourImage colourImageForCore(const sensor_msgs::ImageConstPtr& msg);
/// The message's own pixels as a view, whatever the encoding (for frames the keyframe policy will
/// skip: nothing reads their pixels). Call checkImageMessage first.
core::ColourImage borrowedImageView(const sensor_msgs::ImageConstPtr& msg);

/// Depth in metres (CV_32FC1, 0 = invalid) from a 16UC1/mono16 (times `metres_per_unit_16u`) or
/// 32FC1 (metres) message. Throws InvalidInput for other encodings.
cv::Mat depthToMetres(const sensor_msgs::Image& msg, double metres_per_unit_16u);
/// Throws InvalidInput unless the depth encoding is one depthToMetres accepts.
void checkDepthEncoding(const sensor_msgs::Image& msg);

/// The finite points of a cloud with FLOAT32 fields x, y and z (NaN padding of organised clouds
/// skipped). Throws InvalidInput when the fields are missing, of another type, outside a point,
/// big-endian, or the data is shorter than width, height and the steps say.
Eigen::Matrix3Xd mapPointsFromCloud(const sensor_msgs::PointCloud2& cloud);

core::CameraPose poseFromMsg(const geometry_msgs::Pose& pose);
core::CameraPose poseFromTransform(const geometry_msgs::Transform& transform);
geometry_msgs::Pose poseToMsg(const core::CameraPose& pose);
/// The same pose as a transform (e.g. for /tf: the camera frame in the world frame).
geometry_msgs::Transform transformToMsg(const core::CameraPose& pose);

/// The name a keyframe image gets in pairs.txt and under ~export: "rgb/<stamp, 6 decimals>.png",
/// the TUM layout's naming.
std::string keyframeImageName(double stamp);

/// The whole selection as a message (partial false). `world_frame` goes into the header; its
/// stamp is the newest keyframe's.
view_selection::ViewSelection selectionToMsg(const core::SelectionOutput& snapshot,
                                             const std::string& world_frame);
/// A bounded update: the scalar fields of the whole selection (start view, initial pair, counts),
/// and the keyframes and next view sets of `views` only (valid ids, in that order); partial true,
/// order, completed, isolated and pairs empty.
view_selection::ViewSelection selectionUpdateToMsg(const core::SelectionOutput& snapshot,
                                                   const std::string& world_frame,
                                                   const std::vector<core::ViewId>& views);
/// The undirected pair {a, b} (a < b) as a message.
view_selection::ViewPair pairToMsg(core::ViewId a, core::ViewId b);
/// One keyframe's entry and one view's next view set (with its E values) as the messages hold them.
view_selection::KeyframeInfo keyframeToMsg(const core::SelectionOutput& snapshot,
                                           core::ViewId view);
view_selection::NextViewSet nextViewSetToMsg(const core::SelectionOutput& snapshot,
                                             core::ViewId view);

}  // namespace view_selection::ros_node
