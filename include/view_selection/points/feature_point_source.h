// Sample points without depth: image features matched between keyframes whose frusta overlap,
// checked against the epipolar geometry of the known poses, joined into tracks, triangulated
// with the known poses and refined with Ceres. A point belongs to every keyframe that observes
// it, so a new keyframe can change the point sets of earlier ones (reported as updates).
//
// Bounded: match candidates come from a camera grid (the keyframes whose centres lie within
// kCandidateDepths scene depths, or the most recent ones before anything is triangulated), not
// from a scan of every earlier keyframe; and only the keep_descriptor_views keyframes used most
// recently (inserted or matched) keep their descriptors. An older one's descriptors are
// released and its features reduced to those in tracks (what triangulation still reads), so it
// is matched no more but its points stay and its tracks can still grow through other views.
#pragma once

#include "view_selection/core/camera_grid.h"
#include "view_selection/core/point_source.h"
#include "view_selection/points/triangulation.h"

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include <map>
#include <set>
#include <string>
#include <vector>

namespace view_selection::points {

/// Defaults and their reasons are in docs/design.md ("Feature point source").
struct FeaturePointSourceConfig {
  std::string detector = "orb";      ///< "orb" (default, fast) or "sift"
  int max_features = 2000;           ///< per keyframe
  int max_match_views = 6;           ///< earlier keyframes matched against each new one
  double min_overlap = 0.05;         ///< estimated frustum overlap for a candidate, [0, 1]
  double ratio = 0.8;                ///< Lowe's ratio test: best < ratio * second best
  double max_sampson_px = 4.0;       ///< epipolar check from the known poses [px]
  double max_reprojection_px = 3.0;  ///< after refinement, per observation [px]
  double min_parallax_deg = 2.0;     ///< largest angle between a point's observing rays [deg]
  double huber_px = 1.0;             ///< robust loss scale of the refinement [px]
  int max_refine_iterations = 20;
  /// Keyframes that keep their descriptors (can be matched): the most recently used ones.
  int keep_descriptor_views = 200;

  void visitParameters(core::ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const { core::checkRanges(*this); }
};

/// Per-keyframe work of the last process() call, and running totals. Times are CPU seconds of
/// the process (all threads), i.e. one core's work, not wall time.
struct FeatureStats {
  double extract_seconds = 0.0;      ///< detection and description
  double match_seconds = 0.0;        ///< candidate choice, matching, ratio and epipolar checks
  double triangulate_seconds = 0.0;  ///< tracks, DLT, Ceres, acceptance, point sets
  double refine_seconds = 0.0;       ///< the Ceres part of triangulate_seconds
  size_t features = 0;
  size_t candidates = 0;  ///< earlier keyframes matched against
  size_t scored = 0;      ///< earlier keyframes whose overlap was estimated (the grid's answer)
  size_t matches = 0;     ///< after ratio and epipolar checks
  size_t points = 0;      ///< of the new keyframe
  size_t keyframes = 0;   ///< in totals: keyframes summed over

  FeatureStats& operator+=(const FeatureStats& o);
};

class FeaturePointSource : public core::PointSource {
 public:
  explicit FeaturePointSource(FeaturePointSourceConfig config = {});
  std::string name() const override { return "features"; }
  /// Needs frame.image (8-bit grey, BGR or BGRA; InvalidInput otherwise). Ids must increase.
  core::PointSourceResult process(core::ViewId id, const core::Frame& frame) override;
  void reset() override;
  core::Params params() const override { return core::paramsOf(config_); }

  const FeaturePointSourceConfig& config() const { return config_; }
  const FeatureStats& lastStats() const { return last_; }
  const FeatureStats& totalStats() const { return total_; }
  /// Current points of a keyframe (its valid tracks); empty for an unknown id.
  Eigen::Matrix3Xd pointsOf(core::ViewId id) const;
  /// Earlier keyframes the last keyframe was matched against, best overlap first.
  const std::vector<core::ViewId>& lastCandidates() const { return last_candidates_; }
  /// Tracks with an accepted point.
  size_t validTracks() const;
  /// Keyframes that still hold their descriptors.
  size_t viewsWithDescriptors() const { return in_use_.size(); }
  /// Bytes held (an estimate of the heap use, for tests and reports).
  struct MemoryUse {
    size_t features = 0;     ///< keypoints, their tracks, cameras
    size_t descriptors = 0;  ///< descriptors and the epipolar look-up strips: views kept only
    size_t points = 0;       ///< each view's current point set
    size_t tracks = 0;
    size_t total() const { return features + descriptors + points + tracks; }
  };
  MemoryUse memoryUse() const;

  /// What a keyframe holds in this source.
  struct ViewState {
    core::ViewId id = -1;
    core::PinholeIntrinsics intrinsics;
    core::CameraPose pose;  ///< as given to process() (normalised)
    std::vector<cv::KeyPoint> keypoints;
    cv::Mat descriptors;        ///< one row per keypoint (ORB: 32 x CV_8U, SIFT: 128 x CV_32F)
    std::vector<int> track_of;  ///< per feature, -1 when in no track
    double median_depth = 0.0;  ///< of its points, 0 while it has none
    Eigen::Matrix3Xd emitted;   ///< the point set last reported for it
  };
  struct Track {
    std::vector<std::pair<int, int>> obs;  ///< (view index, feature)
    Eigen::Vector3d point = Eigen::Vector3d::Zero();
    bool valid = false;
    bool alive = true;
  };
  /// Everything this source keeps (features, descriptors, tracks), for saving a session and
  /// continuing it exactly. Descriptors are shared with the source, never written by it.
  struct State {
    std::vector<ViewState> views;  ///< arrival order, ascending id
    std::vector<Track> tracks;
  };
  State state() const;
  /// Throws InvalidInput (nothing changes then) for inconsistent data: ids that do not ascend,
  /// descriptors that do not fit the detector or the keypoints (empty: released), a track or
  /// feature index out of range, a feature and its track that disagree.
  void restore(State state);

  /// Estimated share of the two frusta that see the same scene, in [0, 1]: grids of pixels of
  /// each view, back-projected to `depths`, counted where the other view sees them.
  static double frustumOverlap(const TriangulationCamera& a, const TriangulationCamera& b,
                               const std::vector<double>& depths);
  /// Sampson distance [px] of a correspondence (pixel in a, pixel in b) under the fundamental
  /// matrix of the two known cameras.
  static Eigen::Matrix3d fundamental(const TriangulationCamera& from,
                                     const TriangulationCamera& to);
  static double sampsonDistance(const Eigen::Matrix3d& f, const Eigen::Vector2d& from,
                                const Eigen::Vector2d& to);

 private:
  /// Keypoints bucketed in strips for epipolar-band look-ups: strips across x (each sorted by
  /// y) for lines closer to horizontal, strips across y (sorted by x) for the others.
  struct StripIndex {
    static constexpr int kStrip = 16;  // [px]
    std::vector<std::vector<std::pair<float, int>>> by_x, by_y;
    void build(const std::vector<cv::KeyPoint>& keypoints, int width, int height);
    /// Features within `band` px of the line a x + b y + c = 0, appended to `out`.
    void near(const Eigen::Vector3d& line, double band, const std::vector<cv::KeyPoint>& keypoints,
              std::vector<int>& out) const;
  };
  struct View : ViewState {
    StripIndex index;  ///< built from keypoints
  };

  /// Features of the other view within kBandFactor * max_sampson_px of the epipolar line are a
  /// new feature's candidates (and the ratio test's competitors); the best must then pass the
  /// Sampson check. The wider band admits correspondences whose Sampson distance is small but
  /// whose distance to the line in one image is larger (different scales of the two views).
  static constexpr double kBandFactor = 2.0;
  /// Candidates: keyframes whose centres are within this many scene depths (the largest median
  /// depth of the recent keyframes). A common point within 1.6 depths of one camera is then
  /// more than 2.1 times as far from a camera beyond, past the default matchable gate's
  /// footprint ratio (1.6) and ORB's reliable scale range.
  static constexpr double kCandidateDepths = 5.0;
  static constexpr int kDepthViews = 64;  ///< recent keyframes that give the scene depth
  /// Before anything is triangulated (no depth yet): the most recent keyframes, this many times
  /// max_match_views.
  static constexpr int kRecentFactor = 4;

  /// Up to max_match_views earlier views by overlap, from the grid; `scored_views`: how many
  /// had their overlap estimated.
  std::vector<int> chooseCandidates(const TriangulationCamera& camera, size_t* scored_views);
  std::vector<cv::DMatch> match(const View& next, int candidate) const;
  bool trackHasView(int track, int view) const;
  /// Joins the new view `n`'s matches with each candidate into tracks; returns the tracks changed.
  std::set<int> joinTracks(int n, const std::vector<int>& candidates,
                           const std::vector<std::vector<cv::DMatch>>& matches);
  void triangulateTracks(const std::vector<int>& tracks);
  Eigen::Matrix3Xd pointsOfIndex(int view) const;
  void updateMedianDepth(int view);
  /// Marks a view used now (it keeps its descriptors longest).
  void use(int view);
  /// Releases the descriptors of the least recently used views beyond keep_descriptor_views.
  void releaseOld();
  /// Drops a view's descriptors and strips, and its features in no track (indices remapped).
  void release(int view);

  FeaturePointSourceConfig config_;
  cv::Ptr<cv::Feature2D> detector_;
  int norm_ = cv::NORM_HAMMING;
  std::vector<View> views_;                   // arrival order
  std::vector<TriangulationCamera> cameras_;  // same index as views_
  std::map<core::ViewId, int> index_of_;
  std::vector<Track> tracks_;
  std::vector<core::ViewId> last_candidates_;
  core::CameraGrid grid_;  ///< view index -> camera centre
  uint64_t clock_ = 0;     ///< counts uses
  std::vector<uint64_t> last_use_;              ///< by view index
  std::set<std::pair<uint64_t, int>> in_use_;  ///< (last use, view) of views with descriptors
  FeatureStats last_, total_;
  double refine_seconds_ = 0.0;
};

}  // namespace view_selection::points
