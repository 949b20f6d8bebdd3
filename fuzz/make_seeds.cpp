// Seeds for fuzz_state_file: tiny real sessions, one per point source (64 x 48 frames of a
// textured wall seen from a sideways walk), written as state files into the folder given.
#include "view_selection/core/view_selector.h"
#include "view_selection/io/state_file.h"
#include "view_selection/points/image_conversion.h"
#include "view_selection/points/point_source_factory.h"

#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <random>

using namespace view_selection;

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_make_seeds DIR\n");
    return 2;
  }
  cv::Mat wall(48, 200, CV_8UC3);
  std::mt19937 rng(5);
  for (int i = 0; i < 120; ++i)
    cv::circle(wall, {static_cast<int>(rng() % 200), static_cast<int>(rng() % 48)},
               2 + static_cast<int>(rng() % 6), cv::Scalar(rng() % 255, rng() % 255, rng() % 255),
               cv::FILLED);
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
    for (int q = 0; q < 3; ++q) {
      core::Frame f;
      f.stamp = 1.0 + q;
      f.image_name = "rgb/" + std::to_string(q) + ".png";
      f.intrinsics = {60.0, 60.0, 32.0, 24.0, 64, 48};
      f.pose.position = Eigen::Vector3d(0.05 * q, 0.0, 0.0);
      const cv::Mat image = wall(cv::Rect(10 * q, 0, 64, 48)).clone();
      f.image = points::colourImageOf(image);
      cv::Mat depth(48, 64, CV_32FC1, cv::Scalar(2.0f));
      if (std::string(source) != "auto" || q != 1) f.depth = points::depthImageOf(depth);
      try {
        selector.addFrame(f);
      } catch (const core::Error& e) {
        std::fprintf(stderr, "%s frame %d: %s\n", source, q, e.what());
      }
    }
    io::SessionState state = io::captureSession(selector);
    state.producer = "fuzz_make_seeds";
    const std::string path = std::string(argv[1]) + "/" + source + ".state";
    io::writeStateFile(path, state);
    std::printf("%s: %zu keyframes\n", path.c_str(), selector.matrix().size());
  }
  return 0;
}
