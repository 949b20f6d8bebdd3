// evaluate_trajectory: absolute trajectory error of a COLMAP reconstruction against a TUM-layout
// ground truth. Camera centres of the registered images are matched to ground-truth poses by
// image name (through the folder's rgb.txt), aligned by a Sim(3) Umeyama fit, and the residuals
// summarised. Prints "key value" lines; --json writes the same as a JSON object.
#include "command_line.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/eval/trajectory_alignment.h"
#include "view_selection/io/tum_dataset.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>

namespace fs = std::filesystem;
using namespace view_selection::core;
using namespace view_selection::eval;
using namespace view_selection::io;
using view_selection::tools::CommandLine;
using view_selection::tools::UsageError;

namespace {

const char* kUsage =
    R"(usage: evaluate_trajectory --model PATH (--dataset DIR | --groundtruth FILE) [options]

Absolute trajectory error (ATE) of a COLMAP text model against ground truth: the registered
camera centres are aligned to the ground-truth centres by a similarity (Umeyama; scale, rotation,
translation) and the RMSE of the remaining distances is reported, in ground-truth units.

  --model PATH              COLMAP text model folder holding images.txt, or images.txt itself
                            (binary model: colmap model_converter --output_type TXT first)
  --dataset DIR             TUM-layout folder: image names map to frames through rgb.txt, each
                            frame takes the ground-truth pose nearest its stamp
  --groundtruth FILE        alternative: a TUM trajectory; the image name's stem is the stamp
                            (names like 1305031102.175304.png)
  --max-time-difference S   stamp tolerance [s] (default 0.02)
  --no-scale                SE(3) alignment (scale fixed at 1), for metric reconstructions
  --json FILE               also write the result as JSON (alignment, statistics, per image)
  --help                    this text
)";

struct GroundTruthLookup {
  std::map<std::string, Eigen::Vector3d> by_name;
  std::string describe;
};

GroundTruthLookup fromDataset(const std::string& dir, double tolerance) {
  TumDatasetOptions options;
  options.max_time_difference = tolerance;
  const TumDataset dataset = loadTumDataset(dir, options);
  GroundTruthLookup g;
  for (const TumFrame& f : dataset.frames) g.by_name[dataset.imageName(f)] = f.pose.position;
  g.describe = dir + " (" + std::to_string(dataset.frames.size()) + " frames with ground truth)";
  return g;
}

/// Names are resolved lazily against a trajectory: the stem of the name is the stamp.
std::optional<Eigen::Vector3d> poseForStampName(const std::vector<TumPoseEntry>& traj,
                                                const std::string& name, double tolerance) {
  const std::string stem = fs::path(name).stem().string();
  char* end = nullptr;
  const double stamp = std::strtod(stem.c_str(), &end);
  if (end == stem.c_str() || *end != '\0' || !std::isfinite(stamp)) return std::nullopt;
  const TumPoseEntry* best = nullptr;
  for (const TumPoseEntry& e : traj)
    if (!best || std::abs(e.stamp - stamp) < std::abs(best->stamp - stamp)) best = &e;
  if (!best || std::abs(best->stamp - stamp) >= tolerance) return std::nullopt;
  return best->pose.position;
}

/// images.txt of a model folder (or the file itself); a binary model gets the conversion command.
fs::path imagesTxt(fs::path model) {
  if (!fs::is_directory(model)) return model;
  if (!fs::exists(model / "images.txt")) {
    if (fs::exists(model / "images.bin"))
      throw IoError("'" + model.string() +
                    "' is a binary COLMAP model; convert it first: colmap model_converter "
                    "--input_path " +
                    model.string() + " --output_path OUT --output_type TXT");
    throw IoError("'" + model.string() + "' has no images.txt");
  }
  return model / "images.txt";
}

/// The registered images that have ground truth, with it; the others by name.
struct Matched {
  std::vector<const ColmapImagePose*> used;
  std::vector<Eigen::Vector3d> truth;
  std::vector<std::string> unmatched;
};

Matched matchGroundTruth(const std::vector<ColmapImagePose>& images, const CommandLine& cli,
                         double tolerance, GroundTruthLookup& lookup) {
  std::vector<TumPoseEntry> trajectory;
  if (cli.has("dataset")) {
    lookup = fromDataset(*cli.text("dataset"), tolerance);
  } else {
    trajectory = readTumTrajectory(*cli.text("groundtruth"));
    lookup.describe =
        *cli.text("groundtruth") + " (" + std::to_string(trajectory.size()) + " poses)";
  }
  Matched m;
  for (const ColmapImagePose& im : images) {
    std::optional<Eigen::Vector3d> p;
    if (cli.has("dataset")) {
      const auto it = lookup.by_name.find(im.name);
      if (it != lookup.by_name.end()) p = it->second;
    } else {
      p = poseForStampName(trajectory, im.name, tolerance);
    }
    if (!p) {
      m.unmatched.push_back(im.name);
      continue;
    }
    m.used.push_back(&im);
    m.truth.push_back(*p);
  }
  return m;
}

void writeJson(const std::string& path, const fs::path& model, size_t registered,
               const Matched& m, const AlignmentConfig& config, const TrajectoryError& r) {
  nlohmann::json j;
  j["model"] = model.string();
  j["registered"] = registered;
  j["matched"] = m.used.size();
  j["unmatched"] = m.unmatched;
  j["alignment"] = {
      {"type", config.with_scale ? "sim3" : "se3"},
      {"scale", r.alignment.scale},
      {"rotation",
       {{r.alignment.rotation(0, 0), r.alignment.rotation(0, 1), r.alignment.rotation(0, 2)},
        {r.alignment.rotation(1, 0), r.alignment.rotation(1, 1), r.alignment.rotation(1, 2)},
        {r.alignment.rotation(2, 0), r.alignment.rotation(2, 1), r.alignment.rotation(2, 2)}}},
      {"translation",
       {r.alignment.translation.x(), r.alignment.translation.y(), r.alignment.translation.z()}}};
  j["ate"] = {{"rmse", r.rmse}, {"mean", r.mean}, {"median", r.median}, {"max", r.max}};
  nlohmann::json per = nlohmann::json::array();
  for (size_t i = 0; i < m.used.size(); ++i)
    per.push_back({{"name", m.used[i]->name}, {"error", r.errors[i]}});
  j["per_image"] = per;
  std::ofstream out(path);
  if (!(out << j.dump(1) << "\n")) throw IoError("cannot write '" + path + "'");
}

int run(int argc, char** argv) {
  const CommandLine cli(argc, argv,
                        {"model", "dataset", "groundtruth", "max-time-difference", "json"},
                        {"no-scale", "help"});
  if (cli.flag("help")) {
    std::cout << kUsage;
    return 0;
  }
  if (!cli.has("model")) throw UsageError("--model PATH is required (see --help)");
  if (cli.has("dataset") == cli.has("groundtruth"))
    throw UsageError("give exactly one of --dataset DIR and --groundtruth FILE (see --help)");
  const double tolerance = cli.real("max-time-difference", 0.02, 1e-9, 1e6);
  const fs::path model = imagesTxt(*cli.text("model"));
  const std::vector<ColmapImagePose> images = readColmapImagesTxt(model.string());

  GroundTruthLookup lookup;
  const Matched m = matchGroundTruth(images, cli, tolerance, lookup);
  if (!m.unmatched.empty())
    std::fprintf(
        stderr,
        "evaluate_trajectory: %zu registered image(s) without ground truth, left out (first: %s)\n",
        m.unmatched.size(), m.unmatched.front().c_str());
  if (m.used.size() < 3)
    throw InvalidInput("only " + std::to_string(m.used.size()) + " of " +
                       std::to_string(images.size()) + " registered images have ground truth in " +
                       lookup.describe + "; the ATE needs at least 3");

  Eigen::Matrix3Xd est(3, static_cast<Eigen::Index>(m.used.size())), truth(3, est.cols());
  for (size_t i = 0; i < m.used.size(); ++i) {
    est.col(static_cast<Eigen::Index>(i)) = m.used[i]->centre;
    truth.col(static_cast<Eigen::Index>(i)) = m.truth[i];
  }
  AlignmentConfig config;
  config.with_scale = !cli.flag("no-scale");
  const TrajectoryError r = absoluteTrajectoryError(est, truth, config);

  std::printf("model        %s: %zu registered images, %zu with ground truth\n", model.c_str(),
              images.size(), m.used.size());
  std::printf("ground_truth %s\n", lookup.describe.c_str());
  std::printf("alignment    %s, scale %.6g\n", config.with_scale ? "sim3" : "se3",
              r.alignment.scale);
  std::printf("ate_rmse     %.6g\n", r.rmse);
  std::printf("ate_mean     %.6g\n", r.mean);
  std::printf("ate_median   %.6g\n", r.median);
  std::printf("ate_max      %.6g\n", r.max);
  if (cli.has("json")) writeJson(*cli.text("json"), model, images.size(), m, config, r);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return view_selection::tools::runTool("evaluate_trajectory", [&] { return run(argc, argv); });
}
