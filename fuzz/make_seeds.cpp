// Seeds for fuzz_state_file: tiny real sessions, one per point source (64 x 48 frames of a
// textured wall seen from a sideways walk), written as state files into the folder given; and,
// with a second folder, seeds for fuzz_compressed: that wall and its depth as the compressed
// transports carry them (JPEG, PNG, compressedDepth 16UC1 and 32FC1), in the target's layout;
// and, with a third folder, seeds for fuzz_journal: each session's state file after its second
// frame as the base, and the records of its third frame and of a reset to one keyframe after it.
#include "view_selection/core/view_selector.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/ros/compressed_images.h"
#include "view_selection/session/capture.h"
#include "view_selection/session/delta_tracker.h"
#include "view_selection/session/journal.h"
#include "view_selection/session/state_file.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>

using namespace view_selection;

namespace {

/// fuzz_compressed's input: uint32 decoder (0 colour, 1 compressedDepth, 2 compressed depth),
/// uint32 format length, the format, the payload.
void writeCompressedSeed(const std::string& path, uint32_t decoder,
                         const sensor_msgs::CompressedImage& msg) {
  std::ofstream out(path, std::ios::binary);
  const auto length = static_cast<uint32_t>(msg.format.size());
  out.write(reinterpret_cast<const char*>(&decoder), 4);
  out.write(reinterpret_cast<const char*>(&length), 4);
  out.write(msg.format.data(), msg.format.size());
  out.write(reinterpret_cast<const char*>(msg.data.data()),
            static_cast<std::streamsize>(msg.data.size()));
  std::printf("%s: %zu bytes\n", path.c_str(), msg.data.size());
}

void writeCompressedSeeds(const std::string& dir, const cv::Mat& wall) {
  using ros_node::encodeCompressedDepth;
  using ros_node::encodeCompressedImage;
  const cv::Mat image = wall(cv::Rect(0, 0, 64, 48)).clone();
  cv::Mat grey, depth(48, 64, CV_32FC1), millimetres;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  for (int r = 0; r < 48; ++r)
    for (int c = 0; c < 64; ++c)
      depth.at<float>(r, c) = (r * 64 + c) % 29 == 0 ? 0.0f : 0.4f + 0.05f * c;
  depth.convertTo(millimetres, CV_16UC1, 1000.0);
  writeCompressedSeed(dir + "/jpeg_bgr8", 0, encodeCompressedImage(image, "bgr8", "jpeg", 80));
  writeCompressedSeed(dir + "/png_bgr8", 0, encodeCompressedImage(image, "bgr8", "png", 0));
  writeCompressedSeed(dir + "/jpeg_mono8", 0, encodeCompressedImage(grey, "mono8", "jpeg", 80));
  writeCompressedSeed(dir + "/depth_32fc1", 1, encodeCompressedDepth(depth));
  writeCompressedSeed(dir + "/depth_16uc1", 1, encodeCompressedDepth(millimetres));
  sensor_msgs::CompressedImage png16;
  png16.format = "16UC1; png compressed ";
  cv::imencode(".png", millimetres, png16.data);
  writeCompressedSeed(dir + "/png_16uc1", 2, png16);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || argc > 4) {
    std::fprintf(stderr, "usage: fuzz_make_seeds STATE_DIR [COMPRESSED_DIR [JOURNAL_DIR]]\n");
    return 2;
  }
  cv::Mat wall(48, 200, CV_8UC3);
  std::mt19937 rng(5);
  for (int i = 0; i < 120; ++i)
    cv::circle(wall, {static_cast<int>(rng() % 200), static_cast<int>(rng() % 48)},
               2 + static_cast<int>(rng() % 6), cv::Scalar(rng() % 255, rng() % 255, rng() % 255),
               cv::FILLED);
  if (argc >= 3) writeCompressedSeeds(argv[2], wall);
  for (const char* source : {"depth", "features", "map", "auto"}) {
    core::ViewSelectorConfig config;
    config.keyframes.mode = core::KeyframeMode::kEveryFrame;
    points::PointSourceParams params;
    params.depth.grid = 4;
    params.features.max_features = 60;
    core::ViewSelector selector(config, points::makePointSource(source, params));
    if (std::string(source) == "map") {
      Eigen::Matrix3Xd map(3, 30);
      for (int i = 0; i < 30; ++i)
        map.col(i) = Eigen::Vector3d(-1.0 + 0.07 * i, 0.1 * (i % 5), 2.0);
      dynamic_cast<points::MapPointSource&>(selector.pointSource()).setMapPoints(map);
    }
    // fuzz_journal's seed: u32 size of the base, the base, the records.
    std::vector<uint8_t> journal_seed;
    session::DeltaTracker tracker;
    const uint64_t base_id = 0x5eed5eedu;
    for (int q = 0; q < 3; ++q) {
      if (q == 2) {
        session::SessionState base = session::captureSession(selector);
        base.producer = "fuzz_make_seeds";
        base.base_id = base_id;
        const std::vector<uint8_t> bytes = session::encodeState(base);
        const auto n = static_cast<uint32_t>(bytes.size());
        for (int i = 0; i < 4; ++i) journal_seed.push_back(static_cast<uint8_t>(n >> (8 * i)));
        journal_seed.insert(journal_seed.end(), bytes.begin(), bytes.end());
        tracker.markSaved(selector);
      }
      core::Frame f;
      f.stamp = 1.0 + q;
      f.image_name = "rgb/" + std::to_string(q) + ".png";
      f.intrinsics = {60.0, 60.0, 32.0, 24.0, 64, 48};
      f.pose.position = Eigen::Vector3d(0.05 * q, 0.0, 0.0);
      const cv::Mat image = wall(cv::Rect(10 * q, 0, 64, 48)).clone();
      f.image = images::colourImageOf(image);
      cv::Mat depth(48, 64, CV_32FC1, cv::Scalar(2.0f));
      if (std::string(source) != "auto" || q != 1) f.depth = images::depthImageOf(depth);
      try {
        selector.addFrame(f);
      } catch (const core::Error& e) {
        std::fprintf(stderr, "%s frame %d: %s\n", source, q, e.what());
      }
    }
    if (argc == 4 && !journal_seed.empty()) {
      std::vector<uint8_t> record = session::encodeJournalRecord(base_id, 0, tracker.capture(selector));
      journal_seed.insert(journal_seed.end(), record.begin(), record.end());
      // A second record that truncates the session to its first keyframe.
      session::SessionDelta cut = tracker.capture(selector);
      cut.keyframe_count = std::min<uint64_t>(cut.keyframe_count, 1);
      record = session::encodeJournalRecord(base_id, 1, cut);
      journal_seed.insert(journal_seed.end(), record.begin(), record.end());
      const std::string path = std::string(argv[3]) + "/" + source;
      std::ofstream(path, std::ios::binary)
          .write(reinterpret_cast<const char*>(journal_seed.data()),
                 static_cast<std::streamsize>(journal_seed.size()));
      std::printf("%s: %zu bytes\n", path.c_str(), journal_seed.size());
    }
    session::SessionState state = session::captureSession(selector);
    state.producer = "fuzz_make_seeds";
    const std::string path = std::string(argv[1]) + "/" + source + ".state";
    session::writeStateFile(path, state);
    std::printf("%s: %zu keyframes\n", path.c_str(), selector.matrix().size());
  }
  return 0;
}
