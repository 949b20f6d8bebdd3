// The error-resistance matrix E of METHOD.md, kept incrementally: adding keyframe n computes its
// row and its column only; changing a keyframe's point set recomputes its row only (E[a][i]
// depends on X_a, camera i and i's depth map, never on X_i).
#pragma once

#include "view_selection/core/camera_grid.h"
#include "view_selection/core/error_resistance_table.h"
#include "view_selection/core/keyframe_summary.h"
#include "view_selection/core/occlusion_map.h"
#include "view_selection/core/parameters.h"
#include "view_selection/core/types.h"

#include <Eigen/Core>

#include <cstdint>
#include <map>
#include <utility>
#include <vector>

namespace view_selection::core {

/// Which points count for E[i][j] (METHOD.md version 2).
enum class Gate {
  kPaper,      ///< the paper's: every point of X_i visible in j (version 1 of METHOD.md)
  kMatchable,  ///< ours: visible in j, and parallax and pixel-footprint ratio within limits
};
inline constexpr EnumNames<Gate, 2> kGateNames{
    {{Gate::kPaper, "paper"}, {Gate::kMatchable, "matchable"}}};

/// Parameters of E (METHOD.md "The matrix E"); the defaults are the values in force by default.
struct ErrorResistanceConfig {
  /// paper: the five values below are the paper's (0, 0, 10, 0.1, 0) whatever they are set to;
  /// matchable: they are used as set. applyGate() puts the paper's in.
  Gate gate = Gate::kMatchable;
  /// A point counts only where the angle at it between the rays to O_i and O_j is at most this
  /// [deg]; 0 switches the test off.
  double max_parallax_deg = 20.0;
  /// ... and where s = (|O_j X| / f_j) / (|O_i X| / f_i) has max(s, 1/s) at most this; 0: off.
  double max_scale_ratio = 1.6;
  /// E[i][j] is +inf when fewer than max(min_covisible_points, min_covisible_ratio * |X_i|)
  /// points of X_i count.
  int min_covisible_points = 10;
  double min_covisible_ratio = 0.5;
  /// Optional gate: +inf when the optical axes differ by more than this [deg]; 0 disables it
  /// (the paper's mode).
  double max_view_angle_deg = 0.0;
  OcclusionConfig occlusion;  ///< visibility against j's depth map

  /// With gate paper, sets the gate's five values to the paper's; with matchable, nothing.
  void applyGate();
  /// The values in force: a copy with applyGate() done.
  ErrorResistanceConfig inForce() const {
    ErrorResistanceConfig c = *this;
    c.applyGate();
    return c;
  }

  bool operator==(const ErrorResistanceConfig& o) const { return paramsOf(*this) == paramsOf(o); }
  void visitParameters(ParameterVisitor& v);
  /// Throws InvalidArgument naming the first field out of range.
  void validate() const;
};

/// E[i][j] computed from scratch for one ordered pair: the median of r(X; i -> j) over the
/// points of X_i visible in j, or +inf (gates). The incremental matrix stores exactly this.
double computeErrorResistance(const Keyframe& view_i, const Keyframe& view_j,
                              const ErrorResistanceConfig& config);

class ErrorResistanceMatrix {
 public:
  explicit ErrorResistanceMatrix(ErrorResistanceConfig config = {});

  /// Validates the keyframe (intrinsics, pose, finite points; throws InvalidInput), appends it
  /// with the next id and computes row n and column n. Returns its id.
  ViewId addKeyframe(Keyframe keyframe);
  /// Replaces X_id (finite points; throws InvalidInput) and recomputes row id only.
  void setPoints(ViewId id, Eigen::Matrix3Xd points);
  /// New poses for some keyframes (a loop closure corrected them): each keyframe's points move
  /// with it (they keep their camera-frame coordinates, as its depth map does), and the rows and
  /// columns of exactly those keyframes are recomputed, each pair once. Throws InvalidArgument
  /// for an unknown or repeated id and InvalidInput for an invalid pose; nothing changes then.
  void setPoses(const std::vector<std::pair<ViewId, CameraPose>>& poses);
  /// Forgets every keyframe.
  void clear();
  /// Replaces everything with saved keyframes and their finite rows of E (rows[i]: entries of
  /// row i, any order), without recomputing an entry: a saved session continues exactly. Throws
  /// InvalidInput (nothing changes then) for an invalid keyframe or entry (unknown column, the
  /// diagonal, a repeated column, a non-finite or negative value).
  void restore(std::vector<Keyframe> keyframes, const std::vector<std::vector<TableEntry>>& rows);
  /// New parameters (throws InvalidArgument; nothing changes then); when they differ from the
  /// current ones, every entry is recomputed with them.
  void setConfig(const ErrorResistanceConfig& config);

  size_t size() const { return views_.size(); }
  const Keyframe& keyframe(ViewId id) const { return views_.at(static_cast<size_t>(id)).keyframe; }
  /// Changes whenever keyframe `id` changes (View::version).
  std::uint64_t keyframeVersion(ViewId id) const {
    return views_[static_cast<size_t>(id)].version;
  }
  /// The largest keyframe version of views [c * kVersionChunk, (c + 1) * kVersionChunk) (as
  /// ErrorResistanceTable::chunkVersion for rows), and the last version any view got.
  std::uint64_t keyframeChunkVersion(size_t c) const {
    return c < keyframe_chunk_version_.size() ? keyframe_chunk_version_[c] : 0;
  }
  static std::uint64_t lastKeyframeVersionIssued();
  double at(ViewId i, ViewId j) const { return table_.at(i, j); }
  const ErrorResistanceTable& table() const { return table_; }
  /// What the outputs show of each keyframe, by id (chunked: a copy shares it).
  const ChunkedVector<KeyframeSummary>& summaries() const { return summaries_; }
  const ImageNames& imageNames() const { return names_; }
  const ErrorResistanceConfig& config() const { return config_; }
  /// Pairs whose points were projected (not culled by a pair-level test) so far; for benchmarks.
  size_t pairsEvaluated() const { return pairs_evaluated_; }
  /// Keyframes the candidate search compared with a distance bound so far (the camera grid's
  /// and the farthest-reaching ones); for tests and benchmarks.
  size_t candidatesExamined() const { return candidates_examined_; }

  /// A group of nearby points of X_i with a bounding sphere, for culling against a frustum.
  struct PointGroup {
    Eigen::Vector3d centre;
    double radius = 0.0;
    std::uint32_t begin = 0, end = 0;  // range of View::point_order
  };

  /// Per-keyframe data computed once (rotation, frustum, points grouped for culling). The
  /// points are the keyframe's own, held once; the groups index them through point_order.
  struct View {
    Keyframe keyframe;
    Eigen::Matrix3d world_to_camera;              // R^T
    Eigen::Vector3d sphere_centre;                // of all of X_i, world
    double sphere_radius = -1.0;                  // < 0: no points
    double reach = 0.0;  // farthest point from the camera centre; in the matrix: countedReach
    double focal = 0.0;                           // sqrt(fx fy)
    Eigen::Matrix<double, 3, 5> frustum_normals;  // camera frame, inward unit normals
    std::vector<std::uint32_t> point_order;       // columns of keyframe.points, groups contiguous
    std::vector<PointGroup> groups;               // kd-tree leaves of at most kGroupSize points
    /// Unique to this view as made: a keyframe changed (points, pose) gets a new one, so equal
    /// versions mean an unchanged keyframe (the state journal keys on it).
    std::uint64_t version = 0;
  };
  static constexpr std::uint32_t kGroupSize = 16;
  static View makeView(Keyframe keyframe);

  /// Reused storage for one pair's visible points and their r values.
  struct Scratch {
    std::vector<double> x, y, z;  // the counted points in camera-j coordinates (arrays, for r())
    std::vector<double> values;
    std::vector<const PointGroup*> groups;
  };

 private:
  double entry(const View& view_i, const View& view_j);
  /// The views whose pair with `view` (either direction, as `row` says) can be finite: by the
  /// footprint-ratio gate's reach bound through the camera grid, or every view without it.
  /// Ascending ids, `view`'s own excluded.
  void candidates(ViewId id, bool row, std::vector<ViewId>& out);
  /// Adds view `id` to the camera grid and the reach and focal-length bounds.
  void index(ViewId id);
  /// The distance from O_i within which the points that can make an entry of row i finite
  /// lie: the m-th farthest point of X_i, m the co-visibility gate's count (0: none can).
  double countedReach(const View& v) const;
  /// View `id`'s reach becomes `reach`; the largest reach follows (also down).
  void setReach(ViewId id, double reach);
  /// The row of `id` from scratch, over its candidates.
  std::vector<TableEntry> computeRow(ViewId id);

  ErrorResistanceConfig config_;
  std::vector<View> views_;
  ChunkedVector<KeyframeSummary> summaries_;  // of views_, kept with them
  ImageNames names_;
  ErrorResistanceTable table_;
  Scratch scratch_;
  size_t pairs_evaluated_ = 0;
  size_t candidates_examined_ = 0;
  CameraGrid grid_;                 // camera centres, for candidates()
  /// Views past the grid's reach, looked at one by one in the column direction.
  static constexpr size_t kFarViews = 32;
  void updateGridReach();
  /// View `id` was made or replaced: its chunk's keyframe version follows.
  void placed(ViewId id);
  std::vector<std::uint64_t> keyframe_chunk_version_;
  double grid_reach_ = 0.0;         // the (kFarViews + 1)-th largest reach now
  std::multimap<double, ViewId> reaches_;  // every view's counted reach
  double min_focal_ = 0.0, max_focal_ = 0.0;
  std::vector<ViewId> candidates_;  // reused
};

/// The pair computation behind both computeErrorResistance and the matrix, with `config` as it
/// acts (ErrorResistanceConfig::inForce()). `evaluated` is set when the points had to be
/// projected (the pair was not culled by a pair-level test).
double computeErrorResistance(const ErrorResistanceMatrix::View& view_i,
                              const ErrorResistanceMatrix::View& view_j,
                              const ErrorResistanceConfig& config,
                              ErrorResistanceMatrix::Scratch& scratch, bool* evaluated = nullptr);

/// Throws InvalidInput when a keyframe cannot enter the matrix (bad intrinsics, pose or points).
void validateKeyframe(const Keyframe& keyframe);

/// `keyframe` at `pose`: its points moved with it (same camera-frame coordinates), the pose's
/// quaternion normalised.
Keyframe movedKeyframe(Keyframe keyframe, CameraPose pose);

}  // namespace view_selection::core
