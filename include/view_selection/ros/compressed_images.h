// Compressed image transports, decoded (and, for tum_to_bag, encoded) by the node itself with
// OpenCV, so that bags and cameras that publish only compressed topics work without
// image_transport's plugins (Debian packages only its `raw` one). The wire formats are those of
// ROS Noetic's image_transport_plugins:
//  - `compressed` (compressed_image_transport): sensor_msgs/CompressedImage holding a JPEG or PNG
//    file; `format` is "<original encoding>; <jpeg|png> compressed <encoding of the file's
//    pixels>" (e.g. "rgb8; jpeg compressed bgr8", "mono8; png compressed "), or, from older
//    publishers, just "jpeg" / "png".
//  - `compressedDepth` (compressed_depth_image_transport): a 12-byte header (int32 format,
//    float32 depthQuantA, float32 depthQuantB, native byte order) followed by a PNG; `format` is
//    "<16UC1|32FC1>; compressedDepth[ png]". 16UC1 is the PNG as it is; 32FC1 is quantised
//    inverse depth v = A / depth + B, read back as depth = A / (v - B), v = 0 meaning no depth.
// Every decoder validates before it allocates: the payload's own header gives the size, which
// must be plausible. Anything else is core::InvalidInput with the reason.
#pragma once

#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>

#include <opencv2/core.hpp>

#include <string>

namespace view_selection::ros_node {

/// Largest width or height a compressed payload may declare, and the largest pixel count; larger
/// declarations are refused before decoding (a corrupt header must not allocate gigabytes).
inline constexpr int kMaxCompressedSide = 16384;
inline constexpr long long kMaxCompressedPixels = 64LL * 1024 * 1024;

/// A `compressed` image (JPEG or PNG) as a sensor_msgs/Image, header kept, encoding that of the
/// decoded pixels (e.g. "bgr8" for "rgb8; jpeg compressed bgr8", "mono16" for a 16-bit grey PNG).
/// Throws core::InvalidInput when the payload is not a JPEG or PNG, is corrupt or truncated,
/// declares an implausible size, or its pixels do not match what `format` says.
sensor_msgs::ImagePtr decodeCompressedImage(const sensor_msgs::CompressedImage& msg);

/// A `compressedDepth` image as 16UC1 (as sent) or 32FC1 metres (NaN where there is no depth).
/// Throws core::InvalidInput as decodeCompressedImage, also for a missing or non-finite header,
/// an encoding other than 16UC1/mono16/32FC1, and the `rvl` codec (not supported).
sensor_msgs::ImagePtr decodeCompressedDepth(const sensor_msgs::CompressedImage& msg);

/// compressed_image_transport's encoding: `image` (8-bit grey, BGR or RGB as `encoding` says)
/// as JPEG (`jpeg_quality` 1-100) or PNG, with its format string. For tum_to_bag and the tests.
sensor_msgs::CompressedImage encodeCompressedImage(const cv::Mat& image,
                                                   const std::string& encoding,
                                                   const std::string& codec, int jpeg_quality);

/// compressed_depth_image_transport's encoding (its defaults: depth_max 10 m, quantisation 100):
/// CV_16UC1 as a PNG, CV_32FC1 metres as quantised inverse depth; depth that is missing (0, NaN),
/// not below depth_max, or too near to quantise is written as 0 (no depth).
sensor_msgs::CompressedImage encodeCompressedDepth(const cv::Mat& depth, double depth_max = 10.0,
                                                   double depth_quantization = 100.0);

/// The quantisation step of 32FC1 compressedDepth at `depth` [m]: |d depth / d v| = depth^2 / A,
/// with A = q (q + 1). Decoded depth is within half of it of the original (plus float rounding).
double compressedDepthStep(double depth, double depth_quantization = 100.0);

}  // namespace view_selection::ros_node
