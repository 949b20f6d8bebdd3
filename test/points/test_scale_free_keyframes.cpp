// The default keyframe policy, scale_free (issue 20): the same keyframes and the same selection
// whatever the world's unit, every view of a photo collection kept, and about as many keyframes
// as the motion policy on a handheld 30 Hz RGB-D sequence.
#include "view_selection/core/view_selector.h"
#include "view_selection/io/tum_frames.h"
#include "view_selection/images/image_conversion.h"
#include "view_selection/points/point_source_factory.h"
#include "view_selection/sim/synthetic_sequence.h"

#include "support/layers.h"
#include "support/real_data.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include <vector>

namespace view_selection {
namespace {

/// What a run kept and selected: keyframe stamps, final next view sets, pairs.
struct RunResult {
  std::vector<double> keyframe_stamps;
  std::vector<std::vector<ViewId>> final_sets;
  std::vector<std::pair<ViewId, ViewId>> pairs;
};

struct RenderedFrame {
  double stamp;
  CameraPose pose;
  cv::Mat colour;
  cv::Mat depth_m;  // empty without depth
};

std::vector<RenderedFrame> render(const SyntheticSequenceConfig& config, bool depth) {
  const SyntheticSequence sequence(config);
  std::vector<RenderedFrame> frames;
  for (size_t i = 0; i < sequence.size(); ++i) {
    const SyntheticFrame f = sequence.render(i);
    frames.push_back({f.stamp, f.pose, f.colour,
                      depth ? depthToMetres(f.depth, 1.0 / 5000.0) : cv::Mat()});
  }
  return frames;
}

/// The frames with poses (and depth) in metres x `scale`; every parameter of the other stages
/// that is in scene units (depth range, occlusion tolerance) scaled with them. The keyframe
/// policy's are not: it has none.
RunResult runScaled(const std::vector<RenderedFrame>& frames, const PinholeIntrinsics& intrinsics,
                    const std::string& source, double scale, Gate gate = Gate::kMatchable) {
  ViewSelectorConfig config;  // the defaults: keyframe_policy scale_free
  config.matrix.gate = gate;
  config.matrix.occlusion.abs_tolerance *= scale;
  PointSourceParams params;
  params.depth.min_depth *= scale;
  params.depth.max_depth *= scale;
  ViewSelector selector(config, makePointSource(source, params, config.matrix.occlusion));
  RunResult run;
  std::vector<cv::Mat> keep;  // the images must outlive the frames that view them
  for (const RenderedFrame& r : frames) {
    Frame f;
    f.stamp = r.stamp;
    f.image_name = std::to_string(r.stamp) + ".png";
    f.intrinsics = intrinsics;
    f.pose = r.pose;
    f.pose.position *= scale;
    const bool wanted = selector.wantsFrame(f);
    if (wanted) {
      f.image = colourImageOf(r.colour);
      if (!r.depth_m.empty()) {
        keep.push_back(r.depth_m * scale);
        f.depth = depthImageOf(keep.back());
      }
    }
    const FrameResult result = selector.addFrame(f);
    EXPECT_EQ(result.outcome == FrameOutcome::kKeyframe, wanted) << r.stamp;
    if (result.outcome == FrameOutcome::kKeyframe) run.keyframe_stamps.push_back(r.stamp);
  }
  const Selection s = selector.select();
  run.final_sets = s.final_next_views;
  run.pairs = s.pairs;
  return run;
}

void expectSameRun(const RunResult& a, const RunResult& b, const std::string& what) {
  EXPECT_EQ(a.keyframe_stamps, b.keyframe_stamps) << what;
  EXPECT_EQ(a.final_sets, b.final_sets) << what;
  EXPECT_EQ(a.pairs, b.pairs) << what;
}

// The built-in handheld walk with depth, in metres, millimetres and kilometres.
TEST(ScaleFreeKeyframes, SameKeyframesAndSelectionInAnyUnitWithDepth) {
  SyntheticSequenceConfig config;
  config.frames = 150;
  config.intrinsics = syntheticIntrinsics(320, 240);
  const std::vector<RenderedFrame> frames = render(config, true);
  const RunResult metres = runScaled(frames, config.intrinsics, "depth", 1.0);
  // The policy thins the 30 Hz walk (0.7 m/s) and keeps it covered.
  EXPECT_GT(metres.keyframe_stamps.size(), 5u);
  EXPECT_LT(metres.keyframe_stamps.size(), 40u);
  EXPECT_FALSE(metres.pairs.empty());
  expectSameRun(metres, runScaled(frames, config.intrinsics, "depth", 1000.0), "x 1000");
  expectSameRun(metres, runScaled(frames, config.intrinsics, "depth", 0.001), "x 0.001");
  // The overlap counts with fixed limits: the matrix's gate moves no keyframe.
  EXPECT_EQ(runScaled(frames, config.intrinsics, "depth", 1.0, Gate::kPaper).keyframe_stamps,
            metres.keyframe_stamps);
}

// A photo collection without depth (features triangulated with the known poses): a ring of 47
// views 7.5 degrees apart around the box on the table. Every view is kept, in every unit (the
// motion policy keeps 24 of them in metres and all 47 in millimetres).
TEST(ScaleFreeKeyframes, PhotoRingKeepsEveryViewInAnyUnit) {
  SyntheticSequenceConfig config;
  config.frames = 47;
  config.ring_step_deg = 7.5;
  config.write_depth = false;
  config.intrinsics = syntheticIntrinsics(320, 240);
  const std::vector<RenderedFrame> frames = render(config, false);
  const RunResult metres = runScaled(frames, config.intrinsics, "features", 1.0);
  EXPECT_EQ(metres.keyframe_stamps.size(), 47u);
  for (const double scale : {1000.0, 0.001}) {
    const RunResult other = runScaled(frames, config.intrinsics, "features", scale);
    EXPECT_EQ(other.keyframe_stamps, metres.keyframe_stamps) << scale;
  }
}

size_t keyframesOf(const std::filesystem::path& folder, KeyframeMode mode) {
  const TumDataset dataset = loadTumDataset(folder.string());
  ViewSelectorConfig config;
  config.keyframes.mode = mode;
  ViewSelector selector(config,
                        makePointSource(dataset.has_depth ? "depth" : "features", {},
                                        config.matrix.occlusion));
  for (const TumFrame& tum : dataset.frames) {
    Frame probe;
    probe.pose = tum.pose;
    probe.intrinsics = dataset.intrinsics;
    probe.stamp = tum.stamp;
    const bool wanted = selector.wantsFrame(probe);
    selector.addFrame(loadTumFrame(dataset, tum, {wanted && dataset.has_depth,
                                                  wanted && !dataset.has_depth}));
  }
  return selector.matrix().size();
}

// Real data: the handheld 30 Hz kitchen keeps about as many keyframes as motion did (37 of 500;
// issue 20 allows +-30 %), and DTU (49 object views in mm, no depth) keeps every view.
TEST(ScaleFreeKeyframes, KitchenKeepsAboutAsManyAsMotionAndDtuKeepsEveryView) {
  if (const auto kitchen = test::realData("redkitchen-0-499", "ScaleFreeKeyframes kitchen")) {
    EXPECT_EQ(keyframesOf(*kitchen, KeyframeMode::kMotion), 37u);
    const size_t n = keyframesOf(*kitchen, KeyframeMode::kScaleFree);
    EXPECT_GE(n, 26u);
    EXPECT_LE(n, 48u);
  }
  if (const auto dtu = test::realData("dtu-scan24", "ScaleFreeKeyframes DTU"))
    EXPECT_EQ(keyframesOf(*dtu, KeyframeMode::kScaleFree), 49u);
}

}  // namespace
}  // namespace view_selection
