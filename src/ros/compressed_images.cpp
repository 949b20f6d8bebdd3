#include "view_selection/ros/compressed_images.h"

#include "view_selection/core/exceptions.h"

#include <sensor_msgs/image_encodings.h>

#include <boost/make_shared.hpp>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <sstream>

namespace view_selection::ros_node {

namespace enc = sensor_msgs::image_encodings;

namespace {

constexpr uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
constexpr size_t kDepthHeaderBytes = 12;  ///< int32 format, float32 quantA, float32 quantB
constexpr int32_t kInverseDepth = 0;      ///< compressed_depth_image_transport's INV_DEPTH

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(' ');
  if (a == std::string::npos) return {};
  return s.substr(a, s.find_last_not_of(' ') - a + 1);
}

uint32_t bigEndian32(const uint8_t* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | p[3];
}

enum class Codec { kJpeg, kPng };

struct Declared {
  Codec codec;
  int width = 0, height = 0;
};

/// The size a JPEG declares in its frame header (SOFn), after checking that the file starts
/// with SOI and ends with EOI (libjpeg decodes a truncated file into grey, without an error).
Declared jpegSize(const uint8_t* data, size_t size) {
  size_t end = size;
  while (end > 2 && data[end - 1] == 0x00) --end;  // some encoders pad after EOI
  if (end < 4 || data[end - 2] != 0xff || data[end - 1] != 0xd9)
    throw core::InvalidInput("the JPEG is truncated (no end-of-image marker)");
  size_t pos = 2;
  while (pos + 4 <= size) {
    if (data[pos] != 0xff)
      throw core::InvalidInput("the JPEG is corrupt (no marker at byte " + std::to_string(pos) +
                               ")");
    const uint8_t marker = data[pos + 1];
    if (marker == 0xff) {  // fill byte
      ++pos;
      continue;
    }
    if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd7)) {  // no length
      pos += 2;
      continue;
    }
    const size_t length = (size_t{data[pos + 2]} << 8) | data[pos + 3];
    if (length < 2 || pos + 2 + length > size)
      throw core::InvalidInput("the JPEG is truncated (a segment runs past the end)");
    const bool frame_header =
        marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
    if (frame_header) {
      if (length < 8) throw core::InvalidInput("the JPEG's frame header is too short");
      Declared d{Codec::kJpeg};
      d.height = (data[pos + 5] << 8) | data[pos + 6];
      d.width = (data[pos + 7] << 8) | data[pos + 8];
      return d;
    }
    if (marker == 0xda || marker == 0xd9) break;  // scan data before any frame header
    pos += 2 + length;
  }
  throw core::InvalidInput("the JPEG has no frame header (SOF)");
}

/// The size a PNG declares in its IHDR chunk.
Declared pngSize(const uint8_t* data, size_t size) {
  if (size < 8 + 8 + 13 || std::memcmp(data + 12, "IHDR", 4) != 0)
    throw core::InvalidInput("the PNG is truncated or corrupt (no IHDR chunk)");
  const uint32_t w = bigEndian32(data + 16), h = bigEndian32(data + 20);
  Declared d{Codec::kPng};
  d.width =
      w > static_cast<uint32_t>(kMaxCompressedSide) ? kMaxCompressedSide + 1 : static_cast<int>(w);
  d.height =
      h > static_cast<uint32_t>(kMaxCompressedSide) ? kMaxCompressedSide + 1 : static_cast<int>(h);
  return d;
}

/// Checks the payload's kind and declared size, then decodes it as it is (IMREAD_UNCHANGED, as
/// the plugins do): 8 or 16 bits, 1, 3 (BGR) or 4 (BGRA) channels.
cv::Mat decodePayload(const uint8_t* data, size_t size, const std::string& what) {
  if (size == 0) throw core::InvalidInput(what + ": the payload is empty");
  Declared d;
  if (size >= 3 && data[0] == 0xff && data[1] == 0xd8 && data[2] == 0xff)
    d = jpegSize(data, size);
  else if (size >= 8 && std::memcmp(data, kPngSignature, 8) == 0)
    d = pngSize(data, size);
  else {
    std::ostringstream s;
    s << what << ": the payload is neither a JPEG nor a PNG (first bytes";
    for (size_t i = 0; i < std::min<size_t>(size, 4); ++i) s << ' ' << int{data[i]};
    s << ")";
    throw core::InvalidInput(s.str());
  }
  const char* kind = d.codec == Codec::kJpeg ? "JPEG" : "PNG";
  if (d.width <= 0 || d.height <= 0 || d.width > kMaxCompressedSide ||
      d.height > kMaxCompressedSide ||
      static_cast<long long>(d.width) * d.height > kMaxCompressedPixels)
    throw core::InvalidInput(what + ": the " + kind + " declares " + std::to_string(d.width) + "x" +
                             std::to_string(d.height) + " pixels (at most " +
                             std::to_string(kMaxCompressedSide) + " a side)");
  cv::Mat out;
  try {
    out = cv::imdecode(cv::Mat(1, static_cast<int>(size), CV_8UC1, const_cast<uint8_t*>(data)),
                       cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw core::InvalidInput(what + ": the " + kind + " is corrupt (" + e.err + ")");
  }
  if (out.empty())
    throw core::InvalidInput(what + ": the " + kind +
                             " is corrupt or truncated (it does not decode)");
  if (out.cols != d.width || out.rows != d.height)
    throw core::InvalidInput(what + ": the " + kind + " decodes to another size than it declares");
  if ((out.depth() != CV_8U && out.depth() != CV_16U) ||
      (out.channels() != 1 && out.channels() != 3 && out.channels() != 4))
    throw core::InvalidInput(what + ": the " + kind + " decodes to OpenCV type " +
                             std::to_string(out.type()) +
                             ", not 8 or 16 bits of 1, 3 or 4 channels");
  return out;
}

sensor_msgs::ImagePtr toMessage(const cv::Mat& mat, const std::string& encoding,
                                const std_msgs::Header& header) {
  auto msg = boost::make_shared<sensor_msgs::Image>();
  msg->header = header;
  msg->height = static_cast<uint32_t>(mat.rows);
  msg->width = static_cast<uint32_t>(mat.cols);
  msg->encoding = encoding;
  msg->is_bigendian = 0;
  msg->step = static_cast<uint32_t>(mat.cols * mat.elemSize());
  msg->data.resize(static_cast<size_t>(msg->step) * mat.rows);
  for (int r = 0; r < mat.rows; ++r)
    std::memcpy(msg->data.data() + static_cast<size_t>(r) * msg->step, mat.ptr(r), msg->step);
  return msg;
}

int bitsOf(const cv::Mat& m) { return m.depth() == CV_16U ? 16 : 8; }

/// The decoded pixels' encoding by their shape alone (the old "jpeg" / "png" formats).
std::string encodingByShape(const cv::Mat& m) {
  const bool wide = m.depth() == CV_16U;
  switch (m.channels()) {
    case 1:
      return wide ? enc::MONO16 : enc::MONO8;
    case 3:
      return wide ? enc::BGR16 : enc::BGR8;
    default:
      return wide ? enc::BGRA16 : enc::BGRA8;
  }
}

/// Whether `encoding` describes `m`'s pixels; false (not a throw) for unknown encodings.
bool describes(const std::string& encoding, const cv::Mat& m) {
  try {
    return enc::numChannels(encoding) == m.channels() && enc::bitDepth(encoding) == bitsOf(m);
  } catch (const std::exception&) {
    return false;
  }
}

std::string shapeText(const cv::Mat& m) {
  return std::to_string(m.channels()) + " channel(s) of " + std::to_string(bitsOf(m)) + " bits";
}

}  // namespace

sensor_msgs::ImagePtr decodeCompressedImage(const sensor_msgs::CompressedImage& msg) {
  const cv::Mat m = decodePayload(msg.data.data(), msg.data.size(), "compressed image");
  const size_t split = msg.format.find(';');
  if (split == std::string::npos) return toMessage(m, encodingByShape(m), msg.header);
  const std::string original = trim(msg.format.substr(0, split));
  const std::string rest = msg.format.substr(split + 1);
  // "<codec> compressed <pixels' encoding>": the file's channel order (bgr8 for colour).
  std::string stored;
  const size_t word = rest.find("compressed");
  if (word != std::string::npos) stored = trim(rest.substr(word + std::strlen("compressed")));
  std::string encoding;
  if (!stored.empty())
    encoding = stored;
  else if (!original.empty() && !enc::isColor(original) && describes(original, m))
    encoding = original;  // grey, Bayer or 16UC1, stored as they are
  else
    encoding = encodingByShape(m);
  if (!describes(encoding, m))
    throw core::InvalidInput("compressed image: the format '" + msg.format + "' says " + encoding +
                             ", but the payload decodes to " + shapeText(m));
  return toMessage(m, encoding, msg.header);
}

sensor_msgs::ImagePtr decodeCompressedDepth(const sensor_msgs::CompressedImage& msg) {
  const size_t split = msg.format.find(';');
  const std::string encoding = trim(msg.format.substr(0, split));
  const std::string rest = split == std::string::npos ? std::string() : msg.format.substr(split);
  if (split == std::string::npos || rest.find("compressedDepth") == std::string::npos)
    throw core::InvalidInput("compressedDepth: the format '" + msg.format +
                             "' is not '<16UC1|32FC1>; compressedDepth[ png]'");
  if (rest.find("compressedDepth rvl") != std::string::npos)
    throw core::InvalidInput(
        "compressedDepth: the rvl codec is not supported; publish with the png codec "
        "(compressed_depth_image_transport's format parameter)");
  const bool inverse = encoding == enc::TYPE_32FC1;
  if (!inverse && encoding != enc::TYPE_16UC1 && encoding != enc::MONO16)
    throw core::InvalidInput("compressedDepth: encoding '" + encoding +
                             "' (only 16UC1, mono16 and 32FC1 are defined)");
  if (msg.data.size() <= kDepthHeaderBytes)
    throw core::InvalidInput("compressedDepth: the payload has " + std::to_string(msg.data.size()) +
                             " bytes, no room for its 12-byte header and a PNG");
  int32_t format = 0;
  float quant_a = 0.0f, quant_b = 0.0f;
  std::memcpy(&format, msg.data.data(), 4);
  std::memcpy(&quant_a, msg.data.data() + 4, 4);
  std::memcpy(&quant_b, msg.data.data() + 8, 4);
  const cv::Mat m = decodePayload(msg.data.data() + kDepthHeaderBytes,
                                  msg.data.size() - kDepthHeaderBytes, "compressedDepth");
  if (m.type() != CV_16UC1)
    throw core::InvalidInput("compressedDepth: the PNG holds " + shapeText(m) +
                             ", not one channel of 16 bits");
  if (!inverse) return toMessage(m, encoding, msg.header);
  if (format != kInverseDepth || !std::isfinite(quant_a) || !std::isfinite(quant_b) ||
      !(quant_a > 0.0f)) {
    std::ostringstream s;
    s << "compressedDepth: the 32FC1 header is not inverse depth (format " << format
      << ", depthQuantA " << quant_a << ", depthQuantB " << quant_b << ")";
    throw core::InvalidInput(s.str());
  }
  cv::Mat depth(m.rows, m.cols, CV_32FC1);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int r = 0; r < m.rows; ++r) {
    const auto* v = m.ptr<uint16_t>(r);
    auto* d = depth.ptr<float>(r);
    for (int c = 0; c < m.cols; ++c) {
      const double denominator = static_cast<double>(v[c]) - quant_b;
      d[c] = v[c] != 0 && denominator > 0.0 ? static_cast<float>(quant_a / denominator) : nan;
    }
  }
  return toMessage(depth, enc::TYPE_32FC1, msg.header);
}

sensor_msgs::CompressedImage encodeCompressedImage(const cv::Mat& image,
                                                   const std::string& encoding,
                                                   const std::string& codec, int jpeg_quality) {
  if (codec != "jpeg" && codec != "png")
    throw core::InvalidArgument("compressed image codec '" + codec + "': jpeg or png");
  const bool colour = enc::isColor(encoding);
  if (image.empty() || image.depth() != CV_8U ||
      image.channels() != (colour ? enc::numChannels(encoding) : 1))
    throw core::InvalidArgument("encodeCompressedImage: an 8-bit image of encoding " + encoding);
  cv::Mat bgr = image;
  if (encoding == enc::RGB8) cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);
  if (encoding == enc::RGBA8) cv::cvtColor(image, bgr, cv::COLOR_RGBA2BGR);
  if (encoding == enc::BGRA8) cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
  sensor_msgs::CompressedImage msg;
  msg.format = encoding + "; " + codec + " compressed " + (colour ? "bgr8" : "");
  std::vector<int> params;
  if (codec == "jpeg") params = {cv::IMWRITE_JPEG_QUALITY, jpeg_quality};
  if (!cv::imencode(codec == "jpeg" ? ".jpg" : ".png", bgr, msg.data, params))
    throw core::IoError("cv::imencode (" + codec + ") failed");
  return msg;
}

sensor_msgs::CompressedImage encodeCompressedDepth(const cv::Mat& depth, double depth_max,
                                                   double depth_quantization) {
  if (depth.empty() || (depth.type() != CV_16UC1 && depth.type() != CV_32FC1))
    throw core::InvalidArgument("encodeCompressedDepth: CV_16UC1 or CV_32FC1 depth");
  sensor_msgs::CompressedImage msg;
  int32_t format = kInverseDepth;
  float header[2] = {0.0f, 0.0f};
  cv::Mat png;
  if (depth.type() == CV_16UC1) {
    msg.format = enc::TYPE_16UC1 + "; compressedDepth png";
    png = depth.clone();
    const auto limit = static_cast<uint16_t>(std::min(65535.0, depth_max * 1000.0));
    png.setTo(0, png > limit);  // the plugin's max-depth filter (it takes 16UC1 as millimetres)
  } else {
    msg.format = enc::TYPE_32FC1 + "; compressedDepth png";
    const float a = static_cast<float>(depth_quantization * (depth_quantization + 1.0));
    const float b = static_cast<float>(1.0 - a / depth_max);
    header[0] = a;
    header[1] = b;
    png.create(depth.rows, depth.cols, CV_16UC1);
    for (int r = 0; r < depth.rows; ++r) {
      const auto* d = depth.ptr<float>(r);
      auto* v = png.ptr<uint16_t>(r);
      for (int c = 0; c < depth.cols; ++c) {
        const double q = d[c] > 0.0f && d[c] < depth_max ? a / d[c] + b : 0.0;
        // Truncated, as the plugin's float-to-unsigned-short assignment does.
        v[c] = q >= 1.0 && q < 65536.0 ? static_cast<uint16_t>(q) : 0;
      }
    }
  }
  std::vector<uint8_t> file;
  if (!cv::imencode(".png", png, file, {cv::IMWRITE_PNG_COMPRESSION, 1}))
    throw core::IoError("cv::imencode (png) failed on the depth image");
  msg.data.resize(kDepthHeaderBytes + file.size());
  std::memcpy(msg.data.data(), &format, 4);
  std::memcpy(msg.data.data() + 4, header, 8);
  std::memcpy(msg.data.data() + kDepthHeaderBytes, file.data(), file.size());
  return msg;
}

double compressedDepthStep(double depth, double depth_quantization) {
  return depth * depth / (depth_quantization * (depth_quantization + 1.0));
}

}  // namespace view_selection::ros_node
