// The compressed transports the node decodes itself (no master): compressed_image_transport's
// JPEG and PNG with its format strings, compressedDepth's 12-byte header + PNG for 16UC1 and
// 32FC1 (quantised inverse depth), and corrupt, truncated or implausible payloads refused with
// the reason. On the kitchen's first frame when ../shared/data is there, else a synthetic one.
#include "view_selection/core/exceptions.h"
#include "view_selection/ros/compressed_images.h"
#include "view_selection/ros/conversions.h"

#include "../support/real_data.h"

#include <gtest/gtest.h>
#include <sensor_msgs/image_encodings.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

namespace {

using namespace view_selection;
using namespace view_selection::ros_node;
namespace enc = sensor_msgs::image_encodings;

/// The kitchen's first colour image (BGR) and depth (metres, 0 = none), or synthetic ones.
struct Frame {
  cv::Mat bgr, depth_m;
};
Frame frame() {
  Frame f;
  if (const auto root = test::realData("redkitchen-0-499", "CompressedImages")) {
    f.bgr = cv::imread((*root / "rgb" / "1000.000000.jpg").string(), cv::IMREAD_COLOR);
    const cv::Mat units =
        cv::imread((*root / "depth" / "1000.000000.png").string(), cv::IMREAD_UNCHANGED);
    units.convertTo(f.depth_m, CV_32FC1, 1.0 / 5000.0);  // TUM PNG: 5000 units a metre
  }
  if (f.bgr.empty()) {
    f.bgr.create(120, 160, CV_8UC3);
    // Smooth noise from a generator of its own (the global one's state depends on the tests
    // run before): JPEG's error on it, as on a photograph, is a few grey levels. (Noise blurred
    // at 2 px gave 4.04 here, over the bound below, so the test failed without the kitchen.)
    cv::RNG rng(20261205);
    rng.fill(f.bgr, cv::RNG::UNIFORM, 0, 255);
    cv::GaussianBlur(f.bgr, f.bgr, {0, 0}, 3.0);
    f.depth_m.create(120, 160, CV_32FC1);
    for (int r = 0; r < 120; ++r)
      for (int c = 0; c < 160; ++c)
        f.depth_m.at<float>(r, c) = (r + c) % 37 == 0 ? 0.0f : 0.5f + 0.03f * c;
  }
  return f;
}

cv::Mat viewOf(const sensor_msgs::Image& msg) {
  checkImageMessage(
      msg, msg.encoding == enc::TYPE_32FC1 || msg.encoding == enc::TYPE_16UC1 ? "depth" : "image");
  return imageView(msg);
}

TEST(CompressedImages, JpegAsCompressedImageTransportWritesIt) {
  const Frame f = frame();
  cv::Mat rgb;
  cv::cvtColor(f.bgr, rgb, cv::COLOR_BGR2RGB);
  sensor_msgs::CompressedImage msg = encodeCompressedImage(rgb, enc::RGB8, "jpeg", 80);
  EXPECT_EQ(msg.format, "rgb8; jpeg compressed bgr8");
  msg.header.stamp = ros::Time(1305031102, 175304000);
  msg.header.frame_id = "/openni_rgb_optical_frame";
  const sensor_msgs::ImagePtr out = decodeCompressedImage(msg);
  EXPECT_EQ(out->header.stamp, msg.header.stamp);
  EXPECT_EQ(out->header.frame_id, msg.header.frame_id);
  EXPECT_EQ(out->encoding, enc::BGR8);  // the file's own channel order, no conversion
  const cv::Mat decoded = viewOf(*out);
  ASSERT_EQ(decoded.size(), f.bgr.size());
  // JPEG at quality 80 (the plugin's default): close, not equal. A channel swap would be far off.
  cv::Mat diff;
  cv::absdiff(decoded, f.bgr, diff);
  const double mean = cv::mean(diff.reshape(1))[0];
  EXPECT_LT(mean, 4.0);
  EXPECT_GT(mean, 0.0);
  cv::Mat swapped;
  cv::cvtColor(f.bgr, swapped, cv::COLOR_BGR2RGB);
  cv::absdiff(decoded, swapped, diff);
  EXPECT_GT(cv::mean(diff.reshape(1))[0], mean);
}

TEST(CompressedImages, PngIsExactAndGreyKeepsItsEncoding) {
  const Frame f = frame();
  const sensor_msgs::CompressedImage colour = encodeCompressedImage(f.bgr, enc::BGR8, "png", 0);
  EXPECT_EQ(colour.format, "bgr8; png compressed bgr8");
  const sensor_msgs::ImagePtr out = decodeCompressedImage(colour);
  EXPECT_EQ(out->encoding, enc::BGR8);
  EXPECT_EQ(cv::norm(viewOf(*out), f.bgr, cv::NORM_INF), 0.0);

  cv::Mat grey;
  cv::cvtColor(f.bgr, grey, cv::COLOR_BGR2GRAY);
  const sensor_msgs::CompressedImage mono = encodeCompressedImage(grey, enc::MONO8, "jpeg", 95);
  EXPECT_EQ(mono.format, "mono8; jpeg compressed ");  // the plugin's trailing space
  EXPECT_EQ(decodeCompressedImage(mono)->encoding, enc::MONO8);

  // Older publishers write only "jpeg" / "png": the encoding follows the decoded pixels.
  sensor_msgs::CompressedImage old = colour;
  old.format = "png";
  EXPECT_EQ(decodeCompressedImage(old)->encoding, enc::BGR8);
  old = mono;
  old.format = "jpeg";
  EXPECT_EQ(decodeCompressedImage(old)->encoding, enc::MONO8);
}

TEST(CompressedImages, Depth16uIsExact) {
  const Frame f = frame();
  cv::Mat mm;
  f.depth_m.convertTo(mm, CV_16UC1, 1000.0);
  const sensor_msgs::CompressedImage msg = encodeCompressedDepth(mm);
  EXPECT_EQ(msg.format, "16UC1; compressedDepth png");
  const sensor_msgs::ImagePtr out = decodeCompressedDepth(msg);
  EXPECT_EQ(out->encoding, enc::TYPE_16UC1);
  cv::Mat expected = mm.clone();
  expected.setTo(0, mm > 10000);  // the plugin's 10 m filter
  EXPECT_EQ(cv::norm(viewOf(*out), expected, cv::NORM_INF), 0.0);
}

TEST(CompressedImages, Depth32fWithinItsQuantisation) {
  const Frame f = frame();
  cv::Mat depth = f.depth_m.clone();
  depth.setTo(std::numeric_limits<float>::quiet_NaN(), f.depth_m == 0.0f);  // TUM's 32FC1 bags
  const sensor_msgs::CompressedImage msg = encodeCompressedDepth(depth);
  EXPECT_EQ(msg.format, "32FC1; compressedDepth png");
  const sensor_msgs::ImagePtr out = decodeCompressedDepth(msg);
  EXPECT_EQ(out->encoding, enc::TYPE_32FC1);
  const cv::Mat back = viewOf(*out);
  const cv::Mat metres = depthToMetres(*out, 0.001);
  size_t valid = 0;
  double worst = 0.0;
  for (int r = 0; r < depth.rows; ++r)
    for (int c = 0; c < depth.cols; ++c) {
      const float d = f.depth_m.at<float>(r, c), b = back.at<float>(r, c);
      if (d == 0.0f || d >= 10.0f) {
        EXPECT_TRUE(std::isnan(b)) << r << "," << c;  // no depth stays no depth
        EXPECT_EQ(metres.at<float>(r, c), 0.0f);
        continue;
      }
      ++valid;
      // Truncation: the decoded depth is at most one step farther, never nearer (float rounding).
      const double step = compressedDepthStep(d);
      EXPECT_GE(b, d - 1e-5 * d) << r << "," << c;
      EXPECT_LE(b, d + step + 1e-5 * d) << r << "," << c;
      worst = std::max(worst, (b - d) / step);
    }
  EXPECT_GT(valid, static_cast<size_t>(depth.total() / 2));
  EXPECT_GT(worst, 0.5);  // it is quantised: not the exact depth
  EXPECT_NEAR(compressedDepthStep(1.0), 1.0 / 10100.0, 1e-12);
}

TEST(CompressedImages, Depth32fHeaderReadAsThePluginWritesIt) {
  // Written by hand as compressed_depth_image_transport lays it out: int32 INV_DEPTH (0), float
  // depthQuantA = 100 * 101, float depthQuantB = 1 - A / 10; a 2x1 PNG with v = 1000 and 0.
  cv::Mat v(1, 2, CV_16UC1);
  v.at<uint16_t>(0, 0) = 1000;
  v.at<uint16_t>(0, 1) = 0;
  std::vector<uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", v, png));
  sensor_msgs::CompressedImage msg;
  msg.format = "32FC1; compressedDepth";  // the format before the rvl codec came
  const int32_t format = 0;
  const float a = 10100.0f, b = 1.0f - 10100.0f / 10.0f;
  msg.data.resize(12);
  std::memcpy(msg.data.data(), &format, 4);
  std::memcpy(msg.data.data() + 4, &a, 4);
  std::memcpy(msg.data.data() + 8, &b, 4);
  msg.data.insert(msg.data.end(), png.begin(), png.end());
  const sensor_msgs::ImagePtr decoded = decodeCompressedDepth(msg);
  const cv::Mat depth = viewOf(*decoded);
  EXPECT_NEAR(depth.at<float>(0, 0), 10100.0 / (1000.0 + 1009.0), 1e-5);  // depth = A / (v - B)
  EXPECT_TRUE(std::isnan(depth.at<float>(0, 1)));
}

/// The decoder's error for `msg`, "" when it decoded.
std::string errorOf(const sensor_msgs::CompressedImage& msg, bool depth) {
  try {
    depth ? decodeCompressedDepth(msg) : decodeCompressedImage(msg);
  } catch (const core::InvalidInput& e) {
    return e.what();
  }
  return "";
}

TEST(CompressedImages, CorruptPayloadsAreRefusedWithTheReason) {
  const Frame f = frame();
  const sensor_msgs::CompressedImage jpeg = encodeCompressedImage(f.bgr, enc::BGR8, "jpeg", 80);
  const sensor_msgs::CompressedImage png = encodeCompressedImage(f.bgr, enc::BGR8, "png", 0);

  sensor_msgs::CompressedImage m = jpeg;
  m.data.resize(m.data.size() / 2);  // libjpeg would fill the rest with grey, without an error
  EXPECT_NE(errorOf(m, false).find("truncated"), std::string::npos) << errorOf(m, false);
  m = png;
  m.data.resize(m.data.size() - 100);
  EXPECT_NE(errorOf(m, false).find("PNG"), std::string::npos) << errorOf(m, false);
  m = png;
  for (size_t i = m.data.size() / 2; i < m.data.size() / 2 + 64; ++i) m.data[i] ^= 0x5a;
  EXPECT_NE(errorOf(m, false).find("corrupt"), std::string::npos) << errorOf(m, false);
  m = png;
  m.data[16] = 0x7f;  // IHDR width: 2 billion pixels
  EXPECT_NE(errorOf(m, false).find("declares"), std::string::npos) << errorOf(m, false);
  m = jpeg;
  m.data.clear();
  EXPECT_NE(errorOf(m, false).find("empty"), std::string::npos);
  m.data = {'G', 'I', 'F', '8', '9', 'a'};
  EXPECT_NE(errorOf(m, false).find("neither a JPEG nor a PNG"), std::string::npos);
  m = jpeg;
  m.format = "mono16; jpeg compressed mono16";
  EXPECT_NE(errorOf(m, false).find("decodes to 3 channel(s) of 8 bits"), std::string::npos)
      << errorOf(m, false);

  cv::Mat mm;
  f.depth_m.convertTo(mm, CV_16UC1, 1000.0);
  const sensor_msgs::CompressedImage depth = encodeCompressedDepth(mm);
  m = depth;
  m.data.resize(12);
  EXPECT_NE(errorOf(m, true).find("12-byte header"), std::string::npos) << errorOf(m, true);
  m = depth;
  m.format = "16UC1; compressedDepth rvl";
  EXPECT_NE(errorOf(m, true).find("rvl"), std::string::npos);
  m = depth;
  m.format = "8UC3; compressedDepth png";
  EXPECT_NE(errorOf(m, true).find("only 16UC1"), std::string::npos);
  m = depth;
  m.format = "32FC1; compressedDepth png";  // a 16UC1 header: quantA 0
  EXPECT_NE(errorOf(m, true).find("not inverse depth"), std::string::npos) << errorOf(m, true);
  m = encodeCompressedDepth(f.depth_m);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(m.data.data() + 4, &nan, 4);
  EXPECT_NE(errorOf(m, true).find("not inverse depth"), std::string::npos);
  m = png;  // a colour PNG behind a depth header
  m.format = "16UC1; compressedDepth png";
  m.data.insert(m.data.begin(), 12, 0);
  EXPECT_NE(errorOf(m, true).find("not one channel of 16 bits"), std::string::npos)
      << errorOf(m, true);
}

TEST(CompressedImages, RandomDamageNeverCrashes) {
  const Frame f = frame();
  cv::Mat small;
  cv::resize(f.bgr, small, {64, 48});
  cv::Mat depth_small;
  cv::resize(f.depth_m, depth_small, {64, 48}, 0, 0, cv::INTER_NEAREST);
  const sensor_msgs::CompressedImage good[] = {encodeCompressedImage(small, enc::BGR8, "jpeg", 80),
                                               encodeCompressedImage(small, enc::BGR8, "png", 0),
                                               encodeCompressedDepth(depth_small)};
  std::mt19937 rng(19);
  size_t refused = 0, decoded = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const size_t which = trial % 3;
    sensor_msgs::CompressedImage m = good[which];
    const int flips = 1 + static_cast<int>(rng() % 8);
    for (int i = 0; i < flips; ++i) m.data[rng() % m.data.size()] = static_cast<uint8_t>(rng());
    if (rng() % 3 == 0) m.data.resize(rng() % m.data.size());
    try {
      // Damage inside the entropy-coded pixels decodes (JPEG cannot tell); what decodes is a
      // well-formed message of the size the payload declares.
      const sensor_msgs::ImagePtr out =
          which == 2 ? decodeCompressedDepth(m) : decodeCompressedImage(m);
      EXPECT_NO_THROW(checkImageMessage(*out, which == 2 ? "depth" : "image"));
      ++decoded;
    } catch (const core::InvalidInput&) {
      ++refused;
    }
  }
  EXPECT_GT(refused, 50u);
  std::printf("[ damage   ] %zu decoded (damage inside the pixels), %zu refused\n", decoded,
              refused);
}

}  // namespace
