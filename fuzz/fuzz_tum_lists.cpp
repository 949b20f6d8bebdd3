// TUM folder lists: rgb.txt, depth.txt and groundtruth.txt from one input (split at NUL bytes),
// each parsed, then associated by stamps as select_views does, and the whole folder loaded.
#include "fuzz_target.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/tum_dataset.h"

#include <filesystem>

using namespace view_selection;

VIEW_SELECTION_FUZZ_TARGET(tum_lists) {
  const char* names[3] = {"rgb.txt", "depth.txt", "groundtruth.txt"};
  const std::string folder = fuzz::scratchFolder() + "/tum";
  std::filesystem::create_directories(folder);
  size_t start = 0;
  for (int part = 0; part < 3; ++part) {
    size_t end = start;
    while (end < size && data[end] != 0) ++end;
    fuzz::writeScratch(std::string("tum/") + names[part], data + std::min(start, size),
                       std::min(end, size) - std::min(start, size));
    start = end + 1;
  }
  const std::string camera = "fx: 525\nfy: 525\ncx: 319.5\ncy: 239.5\nwidth: 640\nheight: 480\n";
  fuzz::writeScratch("tum/camera.yaml", reinterpret_cast<const uint8_t*>(camera.data()),
                     camera.size());
  std::vector<io::TumImageEntry> rgb, depth;
  std::vector<io::TumPoseEntry> poses;
  try {
    rgb = io::readTumImageList(folder + "/rgb.txt");
    depth = io::readTumImageList(folder + "/depth.txt");
    poses = io::readTumTrajectory(folder + "/groundtruth.txt");
  } catch (const core::Error&) {
  }
  for (const auto& p : poses)
    if (!p.pose.isValid()) fuzz::broken("readTumTrajectory returned an invalid pose");
  std::vector<double> a, b;
  for (const auto& e : rgb) a.push_back(e.stamp);
  for (const auto& e : depth) b.push_back(e.stamp);
  const auto pairs = io::associateStamps(a, b, 0.02);
  for (const auto& [i, j] : pairs)
    if (i >= a.size() || j >= b.size()) fuzz::broken("associateStamps: index out of range");
  try {
    const io::TumDataset dataset = io::loadTumDataset(folder);
    for (const auto& f : dataset.frames) dataset.imageName(f);
  } catch (const core::Error&) {
  }
}
