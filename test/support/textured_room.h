// A textured box room, ray-cast exactly: grey images (and optionally depth) for any camera,
// for tests of the feature point source. Each wall carries its own seeded random texture of
// discs and rectangles (plenty of corners), so features match only where the walls overlap.
#pragma once

#include "view_selection/core/types.h"

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include "support/layers.h"

namespace view_selection::test {

class TexturedRoom {
 public:
  /// Room [-half, half] per axis [m]; textures at `texels_per_metre`.
  explicit TexturedRoom(Eigen::Vector3d half = Eigen::Vector3d(3.0, 1.5, 3.0),
                        double texels_per_metre = 200.0, unsigned seed = 7)
      : half_(std::move(half)), texels_per_metre_(texels_per_metre) {
    std::mt19937 rng(seed);
    for (int face = 0; face < 6; ++face) {
      const int axis = face / 2;
      const int ua = (axis + 1) % 3, va = (axis + 2) % 3;
      const int w = static_cast<int>(std::ceil(2.0 * half_[ua] * texels_per_metre_)) + 2;
      const int h = static_cast<int>(std::ceil(2.0 * half_[va] * texels_per_metre_)) + 2;
      cv::Mat tex(h, w, CV_8UC1, cv::Scalar(128));
      std::uniform_int_distribution<int> grey(20, 235), x(0, w - 1), y(0, h - 1), size(3, 18);
      const int shapes = w * h / 60;
      for (int s = 0; s < shapes; ++s) {
        // One draw at a time, in the order gcc evaluated them as arguments (unspecified order).
        const int cy = y(rng), cx = x(rng);
        const cv::Point c(cx, cy);
        const int g = grey(rng);
        if (s % 2 == 0) {
          const int r = size(rng);
          cv::circle(tex, c, r, cv::Scalar(g), cv::FILLED, cv::LINE_AA);
        } else {
          const int sy = size(rng), sx = size(rng);
          cv::rectangle(tex, c, c + cv::Point(sx * 2, sy * 2), cv::Scalar(g), cv::FILLED,
                        cv::LINE_AA);
        }
      }
      cv::GaussianBlur(tex, tex, cv::Size(3, 3), 0.7);
      textures_[static_cast<size_t>(face)] = tex;
    }
  }

  const Eigen::Vector3d& half() const { return half_; }

  /// Distance of a point to the nearest wall [m].
  double distanceToSurface(const Eigen::Vector3d& p) const {
    double d = 1e300;
    for (int a = 0; a < 3; ++a) d = std::min(d, std::abs(half_[a] - std::abs(p[a])));
    return d;
  }

  /// Grey image rendered with 2 x 2 samples per pixel; `depth` (CV_32FC1 z-depth) if not null.
  cv::Mat render(const PinholeIntrinsics& k, const CameraPose& pose,
                 cv::Mat* depth = nullptr) const {
    cv::Mat image(k.height, k.width, CV_8UC1);
    if (depth) depth->create(k.height, k.width, CV_32FC1);
    const Eigen::Matrix3d r = pose.rotation();
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) {
        double sum = 0.0;
        for (int s = 0; s < 4; ++s) {
          const Eigen::Vector2d px(u - 0.25 + 0.5 * (s % 2), v - 0.25 + 0.5 * (s / 2));
          sum += sample(pose.position, r * k.backProject(px), nullptr);
        }
        image.at<uchar>(v, u) = static_cast<uchar>(std::clamp(sum / 4.0 + 0.5, 0.0, 255.0));
        if (depth) {
          double t = 0.0;
          sample(pose.position, r * k.backProject(Eigen::Vector2d(u, v)), &t);
          depth->at<float>(v, u) = static_cast<float>(t);  // z-depth: the ray has z = 1
        }
      }
    }
    return image;
  }

 private:
  /// Grey value where the ray from `o` along `d` meets the walls; `t_out` its parameter.
  double sample(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double* t_out) const {
    double t_best = 1e300;
    int face = 0;
    for (int a = 0; a < 3; ++a) {
      if (std::abs(d[a]) < 1e-12) continue;
      const double wall = d[a] > 0 ? half_[a] : -half_[a];
      const double t = (wall - o[a]) / d[a];
      if (t > 0 && t < t_best) {
        t_best = t;
        face = 2 * a + (d[a] > 0 ? 1 : 0);
      }
    }
    if (t_out) *t_out = t_best;
    const Eigen::Vector3d p = o + t_best * d;
    const int axis = face / 2;
    const int ua = (axis + 1) % 3, va = (axis + 2) % 3;
    const double tu = (p[ua] + half_[ua]) * texels_per_metre_;
    const double tv = (p[va] + half_[va]) * texels_per_metre_;
    const cv::Mat& tex = textures_[static_cast<size_t>(face)];
    // Bilinear lookup.
    const int x0 = std::clamp(static_cast<int>(std::floor(tu)), 0, tex.cols - 2);
    const int y0 = std::clamp(static_cast<int>(std::floor(tv)), 0, tex.rows - 2);
    const double fx = std::clamp(tu - x0, 0.0, 1.0), fy = std::clamp(tv - y0, 0.0, 1.0);
    const double a = tex.at<uchar>(y0, x0), b = tex.at<uchar>(y0, x0 + 1);
    const double c = tex.at<uchar>(y0 + 1, x0), e = tex.at<uchar>(y0 + 1, x0 + 1);
    return (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * c + fx * e);
  }

  Eigen::Vector3d half_;
  double texels_per_metre_;
  std::array<cv::Mat, 6> textures_;
};

}  // namespace view_selection::test
