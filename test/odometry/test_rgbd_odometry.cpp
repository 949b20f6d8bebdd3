// The odometry stand-in (issue 29) on the built-in sequence (exact poses): it tracks, it drifts
// (a little, not zero), and a frame it cannot track is lost with its reason and counted; after a
// run of them it restarts from its last pose.
#include "view_selection/core/exceptions.h"
#include "view_selection/eval/trajectory_alignment.h"
#include "view_selection/odometry/rgbd_odometry.h"
#include "view_selection/sim/synthetic_sequence.h"

#include <gtest/gtest.h>

namespace {

using namespace view_selection;
using Status = odometry::OdometryResult::Status;

class Odometry : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    sim::SyntheticSequenceConfig c;
    c.frames = 60;
    c.intrinsics = sim::syntheticIntrinsics(320, 240);
    sequence_ = new sim::SyntheticSequence(c);
    frames_ = new std::vector<sim::SyntheticFrame>();
    for (size_t q = 0; q < sequence_->size(); ++q) frames_->push_back(sequence_->render(q));
  }
  static void TearDownTestSuite() {
    delete frames_;
    delete sequence_;
  }
  static cv::Mat depthOf(const sim::SyntheticFrame& f) {
    cv::Mat d;
    f.depth.convertTo(d, CV_32F, 1.0 / 5000.0);
    return d;
  }
  static const core::PinholeIntrinsics& k() { return sequence_->config().intrinsics; }
  static sim::SyntheticSequence* sequence_;
  static std::vector<sim::SyntheticFrame>* frames_;
};
sim::SyntheticSequence* Odometry::sequence_ = nullptr;
std::vector<sim::SyntheticFrame>* Odometry::frames_ = nullptr;

TEST_F(Odometry, TracksTheSequenceAndDrifts) {
  for (const char* reference : {"frame", "keyframe"}) {
    odometry::OdometryConfig config;
    config.reference = reference;
    odometry::RgbdOdometryTracker tracker(config);
    Eigen::Matrix3Xd est(3, static_cast<long>(frames_->size())), gt(3, static_cast<long>(frames_->size()));
    long n = 0;
    for (const auto& f : *frames_) {
      const odometry::OdometryResult r = tracker.track(f.stamp, f.colour, depthOf(f), k());
      ASSERT_NE(Status::kLost, r.status) << reference << " at " << f.stamp << ": " << r.reason;
      est.col(n) = r.pose.translation();
      gt.col(n++) = f.pose.position;
    }
    EXPECT_EQ(frames_->size(), tracker.counts().tracked);
    EXPECT_EQ(0u, tracker.counts().lost);
    // Two seconds of walking (1.4 m): odometry, so not exact, but not lost either.
    const double ate = eval::absoluteTrajectoryError(est.leftCols(n), gt.leftCols(n)).rmse;
    EXPECT_GT(ate, 1e-5) << reference;
    EXPECT_LT(ate, 0.05) << reference;
  }
}

TEST_F(Odometry, ABlankImageOrNoDepthIsLostAndCounted) {
  odometry::OdometryConfig config;
  config.restart_after_lost = 3;
  odometry::RgbdOdometryTracker tracker(config);
  const auto& f = *frames_;
  ASSERT_EQ(Status::kInitialised, tracker.track(f[0].stamp, f[0].colour, depthOf(f[0]), k()).status);
  ASSERT_EQ(Status::kTracked, tracker.track(f[1].stamp, f[1].colour, depthOf(f[1]), k()).status);
  const cv::Mat blank(f[2].colour.size(), CV_8UC3, cv::Scalar(128, 128, 128));
  odometry::OdometryResult r = tracker.track(f[2].stamp, blank, depthOf(f[2]), k());
  EXPECT_EQ(Status::kLost, r.status);
  EXPECT_NE(std::string::npos, r.reason.find("blank")) << r.reason;
  const cv::Mat no_depth = cv::Mat::zeros(f[3].depth.size(), CV_32F);
  r = tracker.track(f[3].stamp, f[3].colour, no_depth, k());
  EXPECT_EQ(Status::kLost, r.status);
  EXPECT_NE(std::string::npos, r.reason.find("depth")) << r.reason;
  // Tracking resumes against its reference (frame 1) when the camera is back.
  r = tracker.track(f[4].stamp, f[4].colour, depthOf(f[4]), k());
  EXPECT_EQ(Status::kTracked, r.status) << r.reason;
  EXPECT_EQ(2u, tracker.counts().lost);
  // Lost for restart_after_lost frames in a row: the next usable one restarts at the last pose.
  for (size_t q = 5; q < 8; ++q) EXPECT_EQ(Status::kLost, tracker.track(f[q].stamp, blank, depthOf(f[q]), k()).status);
  r = tracker.track(f[20].stamp, f[20].colour, depthOf(f[20]), k());
  EXPECT_EQ(Status::kRestarted, r.status);
  EXPECT_EQ(1u, tracker.counts().restarts);
  EXPECT_EQ(5u, tracker.counts().lost);
  EXPECT_THROW(tracker.track(0.0, f[0].colour, cv::Mat::zeros(10, 10, CV_32F), k()), core::InvalidInput);
  odometry::OdometryConfig bad;
  bad.reference = "map";
  EXPECT_THROW(bad.validate(), core::InvalidArgument);
}

}  // namespace
