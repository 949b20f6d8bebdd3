// A picture of the selection like the paper's Figure 6a: cameras seen from above, next-view
// edges, completion edges in another colour, the start view and isolated views marked.
#pragma once

#include "view_selection/core/selection_output.h"

#include <opencv2/core.hpp>

#include <string>

namespace view_selection::io {

/// Renders onto the plane of the two main directions of the camera centres (PCA), so any
/// trajectory lies flat. `size` is the image side in pixels.
cv::Mat renderSelectionPlot(const core::SelectionOutput& snapshot, int size = 1000,
                            const std::string& title = "");

/// renderSelectionPlot(...) written as a PNG; throws IoError when it cannot be written.
/// Encodes `image` as PNG and writes it to `path`; throws core::IoError with the reason (a full
/// disk, a read-only folder). For use inside io::writeAtomically.
void writePng(const std::string& path, const cv::Mat& image);

void writeSelectionPlot(const std::string& path, const core::SelectionOutput& snapshot,
                        const std::string& title = "");

}  // namespace view_selection::io
