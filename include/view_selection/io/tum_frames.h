// Turning an associated TUM frame into a core Frame: the one place images and depth PNGs are
// read from a TUM folder, shared by select_views, tum_to_bag and the evaluation.
#pragma once

#include "view_selection/core/frame.h"
#include "view_selection/io/tum_dataset.h"

namespace view_selection::io {

struct FrameLoadOptions {
  bool depth = true;   ///< read and convert the depth PNG (when the dataset has depth)
  bool image = false;  ///< read the colour image (BGR)
};

/// Reads what `options` asks for. Throws IoError naming the file when an image cannot be read,
/// InvalidInput when its content is unusable (e.g. depth of a type other than 16UC1/32FC1).
core::Frame loadTumFrame(const TumDataset& dataset, const TumFrame& frame,
                         const FrameLoadOptions& options);

}  // namespace view_selection::io
