#include "view_selection/io/selection_plot.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/atomic_file.h"

#include <Eigen/Eigenvalues>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <vector>

namespace view_selection::io {

namespace {

const cv::Scalar kBackground(255, 255, 255);
const cv::Scalar kCamera(40, 40, 40);
const cv::Scalar kEdge(200, 140, 60);       // next view set edges (blue-ish, BGR)
const cv::Scalar kCompletion(40, 40, 220);  // completion edges (red)
const cv::Scalar kStart(40, 170, 40);       // start view (green)
const cv::Scalar kIsolated(0, 0, 255);

}  // namespace

cv::Mat renderSelectionPlot(const core::SelectionOutput& snapshot, int size,
                            const std::string& title) {
  const core::ChunkedSelection& selection = snapshot.selection;
  cv::Mat image(size, size, CV_8UC3, kBackground);
  const size_t n = snapshot.size();
  if (n == 0) {
    cv::putText(image, "no keyframes", {20, size / 2}, cv::FONT_HERSHEY_SIMPLEX, 0.8, kCamera, 2,
                cv::LINE_AA);
    return image;
  }
  // Plane of the two main directions of the camera centres: any trajectory lies flat on it.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) mean += snapshot.keyframes[i].pose.position;
  mean /= static_cast<double>(n);
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d d = snapshot.keyframes[i].pose.position - mean;
    cov += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  Eigen::Vector3d ax = eig.eigenvectors().col(2), ay = eig.eigenvectors().col(1);
  if (eig.eigenvalues()(2) < 1e-18) {  // a single position: any plane will do
    ax = Eigen::Vector3d::UnitX();
    ay = Eigen::Vector3d::UnitY();
  }
  std::vector<Eigen::Vector2d> flat(n);
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d d = snapshot.keyframes[i].pose.position - mean;
    flat[i] = {d.dot(ax), d.dot(ay)};
    lo = lo.cwiseMin(flat[i]);
    hi = hi.cwiseMax(flat[i]);
  }
  const double margin = 0.08 * size, top = 60.0;
  const double span = std::max({hi.x() - lo.x(), hi.y() - lo.y(), 1e-9});
  const double scale = (size - 2.0 * margin - top) / span;
  const Eigen::Vector2d centre = 0.5 * (lo + hi);
  auto toPixel = [&](const Eigen::Vector2d& p) {
    return cv::Point2d(size / 2.0 + (p.x() - centre.x()) * scale,
                       top / 2 + size / 2.0 - (p.y() - centre.y()) * scale);
  };
  auto arrow = [&](size_t a, size_t b, const cv::Scalar& colour, int thickness) {
    const cv::Point2d pa = toPixel(flat[a]), pb = toPixel(flat[b]);
    const double length = cv::norm(pb - pa);
    if (length < 1.0) return;
    cv::arrowedLine(image, pa, pb, colour, thickness, cv::LINE_AA, 0, std::min(0.3, 8.0 / length));
  };

  for (size_t i = 0; i < selection.next_views.size() && i < n; ++i)
    for (const core::ViewId j : selection.next_views[i]) arrow(i, static_cast<size_t>(j), kEdge, 1);
  for (const core::CompletedView& c : selection.completed)
    arrow(static_cast<size_t>(c.added_to), static_cast<size_t>(c.view), kCompletion, 2);

  const double tick = 0.04 * size;
  for (size_t i = 0; i < n; ++i) {
    const core::KeyframeSummary& kf = snapshot.keyframes[i];
    const Eigen::Vector3d axis = kf.pose.opticalAxis();
    Eigen::Vector2d dir(axis.dot(ax), -axis.dot(ay));
    const cv::Point2d p = toPixel(flat[i]);
    if (dir.norm() > 1e-6) {
      dir.normalize();
      cv::line(image, p, p + cv::Point2d(dir.x(), dir.y()) * tick, kCamera, 1, cv::LINE_AA);
    }
    const bool start = static_cast<core::ViewId>(i) == selection.start_view;
    const bool isolated = std::find(selection.isolated.begin(), selection.isolated.end(),
                                    static_cast<core::ViewId>(i)) != selection.isolated.end();
    const double h = start ? 6.0 : 4.0;
    cv::rectangle(image, p - cv::Point2d(h, h), p + cv::Point2d(h, h),
                  start ? kStart : (isolated ? kIsolated : kCamera), isolated ? 2 : cv::FILLED,
                  cv::LINE_AA);
  }

  const std::string heading = title.empty() ? "view selection" : title;
  cv::putText(image, heading, {15, 28}, cv::FONT_HERSHEY_SIMPLEX, 0.7, kCamera, 2, cv::LINE_AA);
  const std::string legend = std::to_string(n) + " views, " +
                             std::to_string(selection.pairs.size()) +
                             " pairs; blue: next view sets, red: completion, green: start";
  cv::putText(image, legend, {15, 52}, cv::FONT_HERSHEY_SIMPLEX, 0.5, kCamera, 1, cv::LINE_AA);
  return image;
}

void writePng(const std::string& path, const cv::Mat& image) {
  std::vector<uchar> png;
  try {
    if (!cv::imencode(".png", image, png))
      throw core::IoError("cannot encode '" + path + "' as PNG");
  } catch (const cv::Exception& e) {
    throw core::IoError("cannot encode '" + path + "' as PNG: " + e.what());
  }
  writeFileContents(path, png.data(), png.size());
}

void writeSelectionPlot(const std::string& path, const core::SelectionOutput& snapshot,
                        const std::string& title) {
  const cv::Mat image = renderSelectionPlot(snapshot, 1000, title);
  writePng(path, image);
}

}  // namespace view_selection::io
