// What the outputs show of a keyframe (no points, no depth map), and its image name, kept by the
// matrix beside the keyframes in chunked, shared lists (ChunkedVector), so that an output of
// 100,000 keyframes shares them instead of copying them.
#pragma once

#include "view_selection/core/chunked_vector.h"
#include "view_selection/core/types.h"

#include <cstddef>
#include <string>

namespace view_selection::core {

/// A keyframe without its points and depth map: what the outputs show of it.
struct KeyframeSummary {
  double stamp = 0.0;
  PinholeIntrinsics intrinsics;
  CameraPose pose;
  std::size_t num_points = 0;
  ViewId revisit_of = -1;  ///< Keyframe::revisit_of

  static KeyframeSummary of(const Keyframe& keyframe);
};

/// The name a keyframe's image has when its frame came without one (the node's frames):
/// "rgb/<stamp with 6 decimals>.png", as pairs.txt and ~export name it.
std::string defaultImageName(double stamp);

/// Image names by keyframe id, with no string stored for a name that follows its stamp
/// (defaultImageName): the node's keyframes store none.
class ImageNames {
 public:
  /// Keyframe `id` (the next one) at `stamp` is named `name`; "" means defaultImageName(stamp).
  void push(std::size_t id, double stamp, const std::string& name) {
    if (name.empty() || name == defaultImageName(stamp)) return;
    if (names_.size() < id) names_.resize(id);  // the earlier ones follow their stamps
    names_.push_back(name);
  }
  /// Keyframes from `size` on are forgotten.
  void truncate(std::size_t size) {
    if (names_.size() > size) names_.resize(size);
  }
  void clear() { names_.clear(); }
  /// The name of keyframe `id` at `stamp`.
  std::string at(std::size_t id, double stamp) const {
    return id < names_.size() && !names_[id].empty() ? names_[id] : defaultImageName(stamp);
  }

 private:
  ChunkedVector<std::string> names_;  ///< up to the last stored name; "" follows the stamp
};

}  // namespace view_selection::core
