// The compressed transports the node decodes itself: sensor_msgs/CompressedImage payloads as
// `compressed` colour (JPEG, PNG), `compressedDepth` (12-byte header + PNG) and `compressed`
// depth, with any format string. Input: one byte choosing the decoder, the format text, then the
// payload. A payload must decode to an image of the size it declares, or be refused with
// core::InvalidInput; the decoded message must be one checkImageMessage accepts.
#include "fuzz_target.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/ros/compressed_images.h"
#include "view_selection/ros/conversions.h"

#include <sensor_msgs/image_encodings.h>

#include <cmath>

using namespace view_selection;
namespace enc = sensor_msgs::image_encodings;

VIEW_SELECTION_FUZZ_TARGET(compressed) {
  fuzz::Bytes in(data, size);
  const uint32_t decoder = in.below(3);
  sensor_msgs::CompressedImage msg;
  msg.format = in.text(48);
  msg.data = in.rest();
  sensor_msgs::ImagePtr image;
  try {
    image =
        decoder == 1 ? ros_node::decodeCompressedDepth(msg) : ros_node::decodeCompressedImage(msg);
  } catch (const core::InvalidInput&) {
    return;
  }
  if (!image) fuzz::broken("a decoder returned no image without an error");
  if (image->width == 0 || image->height == 0 ||
      image->width > static_cast<uint32_t>(ros_node::kMaxCompressedSide) ||
      image->height > static_cast<uint32_t>(ros_node::kMaxCompressedSide))
    fuzz::broken("decoded an image of an implausible size");
  try {
    ros_node::checkImageMessage(*image, decoder == 0 ? "image" : "depth");
    if (decoder == 0) {
      (void)ros_node::colourImageForCore(image);
    } else {
      ros_node::checkDepthEncoding(*image);
      const cv::Mat metres = ros_node::depthToMetres(*image, 0.001);
      for (int r = 0; r < metres.rows; ++r)
        for (int c = 0; c < metres.cols; ++c)
          if (std::isnan(metres.at<float>(r, c)) || metres.at<float>(r, c) < 0.0f)
            fuzz::broken("decoded depth converts to a NaN or negative metre value");
    }
  } catch (const core::InvalidInput&) {
    // A decoded image the node refuses (e.g. a 16-bit colour PNG as depth): a clear drop.
    if (decoder == 1) fuzz::broken("compressedDepth decoded to a message the node refuses");
  }
}
