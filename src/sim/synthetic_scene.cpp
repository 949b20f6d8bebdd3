// The synthetic scene: layout of the room and its boxes, procedural textures, ray casting and
// the exact distance to the nearest surface.
#include "synthetic_random.h"
#include "view_selection/core/exceptions.h"
#include "view_selection/sim/synthetic_sequence.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace view_selection::sim {
namespace {

using synthetic::Rng;
using synthetic::streamSeed;

constexpr double kPi = 3.14159265358979323846;

/// A box's yaw as cosine and sine, computed once: ray casting is the inner loop of rendering.
struct Yaw {
  double c = 1.0, s = 0.0;
  explicit Yaw(const Eigen::Vector2d& cos_sin) : c(cos_sin.x()), s(cos_sin.y()) {}
  /// World direction to the box's own axes (rotation about z by -yaw).
  Eigen::Vector3d toLocal(const Eigen::Vector3d& d) const {
    return {c * d.x() + s * d.y(), -s * d.x() + c * d.y(), d.z()};
  }
  Eigen::Vector3d toWorld(const Eigen::Vector3d& d) const {
    return {c * d.x() - s * d.y(), s * d.x() + c * d.y(), d.z()};
  }
};

/// Signed distance to a box's surface in its own axes (negative inside); its magnitude is the
/// exact Euclidean distance to the surface.
double signedBoxDistance(const Eigen::Vector3d& local, const Eigen::Vector3d& half) {
  const Eigen::Vector3d q = local.cwiseAbs() - half;
  const double outside = q.cwiseMax(0.0).norm();
  const double inside = std::min(q.maxCoeff(), 0.0);
  return outside + inside;
}

/// Texture axes of a face: the two box axes other than the face's normal axis.
void faceAxes(int face, int* u_axis, int* v_axis) {
  const int axis = face / 2;
  *u_axis = axis == 0 ? 1 : 0;
  *v_axis = axis == 2 ? 1 : 2;
}

cv::Scalar bgr(const Eigen::Vector3d& c) {
  return cv::Scalar(255.0 * c[0], 255.0 * c[1], 255.0 * c[2]);
}

Eigen::Vector3d randomColour(Rng& rng) {
  return {rng.uniform(0.05, 0.95), rng.uniform(0.05, 0.95), rng.uniform(0.05, 0.95)};
}

/// A feature-rich texture of `w` x `h` texels for a surface of `metres_per_texel`: a base
/// colour, large soft low-contrast blobs, then many sharp shapes (ellipses, convex polygons,
/// rotated rectangles, strokes) whose sizes are spread over a decade and whose contrast varies.
/// No regular pattern, so every corner looks different from its neighbours.
cv::Mat makeTexture(int w, int h, double metres_per_texel, uint64_t seed) {
  Rng rng(seed);
  // Several draws for one call are taken one at a time, last argument first: function arguments
  // have no evaluation order, and gcc's (last first) made the files written so far; clang's
  // differs, which made the textures depend on the compiler.
  const double base_z = rng.uniform(0.3, 0.8), base_y = rng.uniform(0.3, 0.8),
               base_x = rng.uniform(0.3, 0.8);
  const Eigen::Vector3d base(base_x, base_y, base_z);
  cv::Mat tex(h, w, CV_8UC3, bgr(base));
  const double area = w * h * metres_per_texel * metres_per_texel;  // m^2
  const double texels_per_metre = 1.0 / metres_per_texel;
  auto mixed = [&](double contrast) {
    const Eigen::Vector3d c = randomColour(rng);
    return Eigen::Vector3d(base + contrast * (c - base));
  };

  // Soft, low-contrast blobs: drawn and blurred at 1/8 resolution, then enlarged (cheap).
  {
    const int sw = std::max(2, w / 8), sh = std::max(2, h / 8);
    cv::Mat small(sh, sw, CV_8UC3, bgr(base));
    const double small_texels_per_metre = texels_per_metre * sw / w;
    const int soft = std::max(2, static_cast<int>(std::lround(area * 2.0)));
    for (int q = 0; q < soft; ++q) {
      const int cy = rng.below(sh), cx = rng.below(sw);
      const cv::Point centre(cx, cy);
      const double r = rng.uniform(0.2, 0.8) * small_texels_per_metre;
      const cv::Size axes(std::max(1, static_cast<int>(r)),
                          std::max(1, static_cast<int>(r * rng.uniform(0.4, 1.0))));
      const cv::Scalar colour = bgr(mixed(rng.uniform(0.1, 0.3)));
      const double angle = rng.uniform(0, 180);
      cv::ellipse(small, centre, axes, angle, 0, 360, colour, cv::FILLED, cv::LINE_AA);
    }
    cv::GaussianBlur(small, small, cv::Size(0, 0), std::max(0.5, 0.08 * small_texels_per_metre));
    cv::resize(small, tex, tex.size(), 0, 0, cv::INTER_LINEAR);
  }

  const int shapes = std::max(4, static_cast<int>(std::lround(area * 110.0)));
  for (int q = 0; q < shapes; ++q) {
    const double size = rng.logUniform(0.012, 0.2) * texels_per_metre;  // radius [texels]
    const double cy = rng.uniform(-size, h + size), cx = rng.uniform(-size, w + size);
    const cv::Point2d c(cx, cy);
    const cv::Scalar colour = bgr(mixed(rng.uniform(0.25, 1.0)));
    const double angle = rng.uniform(0.0, 2.0 * kPi);
    switch (rng.below(4)) {
      case 0: {  // ellipse
        const cv::Size axes(std::max(1, static_cast<int>(size)),
                            std::max(1, static_cast<int>(size * rng.uniform(0.3, 1.0))));
        cv::ellipse(tex, cv::Point(static_cast<int>(c.x), static_cast<int>(c.y)), axes,
                    angle * 180.0 / kPi, 0, 360, colour, cv::FILLED, cv::LINE_AA);
        break;
      }
      case 1: {  // convex polygon: corners of varied angles
        const int n = 3 + rng.below(4);
        std::vector<double> angles;
        for (int k = 0; k < n; ++k) angles.push_back(rng.uniform(0.0, 2.0 * kPi));
        std::sort(angles.begin(), angles.end());
        std::vector<cv::Point> poly;
        for (double a : angles) {
          const double r = size * rng.uniform(0.6, 1.0);
          poly.emplace_back(static_cast<int>(c.x + r * std::cos(a)),
                            static_cast<int>(c.y + r * std::sin(a)));
        }
        cv::fillConvexPoly(tex, poly, colour, cv::LINE_AA);
        break;
      }
      case 2: {  // rotated rectangle
        const double hw = size, hh = size * rng.uniform(0.2, 1.0);
        const double ca = std::cos(angle), sa = std::sin(angle);
        std::vector<cv::Point> poly;
        for (const auto& [x, y] : {std::pair{-hw, -hh}, {hw, -hh}, {hw, hh}, {-hw, hh}}) {
          poly.emplace_back(static_cast<int>(c.x + ca * x - sa * y),
                            static_cast<int>(c.y + sa * x + ca * y));
        }
        cv::fillConvexPoly(tex, poly, colour, cv::LINE_AA);
        break;
      }
      default: {  // stroke
        const cv::Point a(static_cast<int>(c.x), static_cast<int>(c.y));
        const cv::Point b(static_cast<int>(c.x + 2.0 * size * std::cos(angle)),
                          static_cast<int>(c.y + 2.0 * size * std::sin(angle)));
        const int thickness = std::max(1, static_cast<int>(size * rng.uniform(0.08, 0.25)));
        cv::line(tex, a, b, colour, thickness, cv::LINE_AA);
        break;
      }
    }
  }
  return tex;
}

}  // namespace

void SyntheticSceneConfig::validate() const {
  std::ostringstream msg;
  if (!room_size.allFinite() || room_size.x() < 3.0 || room_size.y() < 3.0 || room_size.z() < 2.0 ||
      room_size.maxCoeff() > 50.0) {
    msg << "room size " << room_size.transpose()
        << " m is out of range (x and y 3..50 m, z 2..50 m)";
  } else if (wall_objects < 0 || wall_objects > 40) {
    msg << "wall_objects = " << wall_objects << " must be 0..40";
  } else if (!(texels_per_metre >= 20.0 && texels_per_metre <= 2000.0)) {
    msg << "texels_per_metre = " << texels_per_metre << " must be 20..2000";
  } else {
    return;
  }
  throw core::InvalidArgument("synthetic scene: " + msg.str());
}

SyntheticScene::SyntheticScene(uint64_t seed, const SyntheticSceneConfig& config)
    : config_(config) {
  config_.validate();
  const Eigen::Vector3d room = config_.room_size;
  Rng rng(streamSeed(seed, 1));

  SceneBox room_box;
  room_box.name = "room";
  room_box.centre = Eigen::Vector3d(0.0, 0.0, room.z() / 2.0);
  room_box.half_size = room / 2.0;
  room_box.inside = true;
  boxes_.push_back(room_box);

  // Footprints (centre, radius) taken so far, to keep objects apart.
  std::vector<std::pair<Eigen::Vector2d, double>> taken;
  auto add = [&](const std::string& name, const Eigen::Vector3d& centre,
                 const Eigen::Vector3d& half, double yaw) {
    SceneBox b;
    b.name = name;
    b.centre = centre;
    b.half_size = half;
    b.yaw = yaw;
    boxes_.push_back(b);
  };

  if (config_.table) {
    const double at_y = rng.uniform(-0.1, 0.1), at_x = rng.uniform(-0.1, 0.1);  // last first
    const Eigen::Vector2d at(at_x, at_y);
    const double yaw = rng.uniform(-0.3, 0.3);
    const Eigen::Vector3d top_half(0.5, 0.35, 0.02);
    const double top_z = 0.75;
    add("table top", Eigen::Vector3d(at.x(), at.y(), top_z - top_half.z()), top_half, yaw);
    const double c = std::cos(yaw), s = std::sin(yaw);
    const double leg = 0.025, leg_height = top_z - 2.0 * top_half.z();
    int n = 0;
    for (double lx : {-1.0, 1.0}) {
      for (double ly : {-1.0, 1.0}) {
        const double x = lx * (top_half.x() - 0.06), y = ly * (top_half.y() - 0.06);
        add("table leg " + std::to_string(++n),
            Eigen::Vector3d(at.x() + c * x - s * y, at.y() + s * x + c * y, leg_height / 2.0),
            Eigen::Vector3d(leg, leg, leg_height / 2.0), yaw);
      }
    }
    const double box_z = rng.uniform(0.08, 0.2), box_y = rng.uniform(0.08, 0.15),
                 box_x = rng.uniform(0.1, 0.18);
    const Eigen::Vector3d box_half(box_x, box_y, box_z);
    const double bx = rng.uniform(-0.2, 0.2), by = rng.uniform(-0.1, 0.1);
    add("box on table",
        Eigen::Vector3d(at.x() + c * bx - s * by, at.y() + s * bx + c * by, top_z + box_half.z()),
        box_half, yaw + rng.uniform(-0.5, 0.5));
    taken.emplace_back(at, top_half.head<2>().norm());
  }

  // Objects along the walls, spread over the four walls in turn.
  for (int q = 0; q < config_.wall_objects; ++q) {
    const int wall = q % 4;  // 0: -x, 1: +x, 2: -y, 3: +y
    const bool along_y = wall < 2;
    const double wall_length = along_y ? room.y() : room.x();
    for (int attempt = 0; attempt < 100; ++attempt) {
      const double width = rng.uniform(0.4, 1.2), depth = rng.uniform(0.3, 0.6);
      const bool tall = rng.uniform() < 0.35;
      const double height =
          tall ? rng.uniform(1.2, std::min(2.0, room.z() - 0.3)) : rng.uniform(0.3, 0.9);
      const double gap = rng.uniform(0.02, 0.15);
      const double along =
          rng.uniform(-wall_length / 2 + width / 2 + 0.1, wall_length / 2 - width / 2 - 0.1);
      const double tilt = rng.uniform(-0.15, 0.15);
      const double sign = wall % 2 == 0 ? -1.0 : 1.0;
      // The extra 0.1 m keeps a tilted box's back corners inside the wall.
      const double from_centre = (along_y ? room.x() : room.y()) / 2 - gap - depth / 2 - 0.1;
      Eigen::Vector2d at = along_y ? Eigen::Vector2d(sign * from_centre, along)
                                   : Eigen::Vector2d(along, sign * from_centre);
      const double radius = std::hypot(width, depth) / 2.0;
      bool clear = true;
      for (const auto& [c, r] : taken) clear = clear && (at - c).norm() > r + radius + 0.05;
      if (!clear) continue;
      // Its own x axis runs along the wall.
      const double yaw = (along_y ? kPi / 2 : 0.0) + tilt;
      add((tall ? "shelf " : "box ") + std::to_string(q + 1),
          Eigen::Vector3d(at.x(), at.y(), height / 2.0),
          Eigen::Vector3d(width / 2.0, depth / 2.0, height / 2.0), yaw);
      taken.emplace_back(at, radius);
      break;
    }
  }

  for (size_t b = 0; b < boxes_.size(); ++b) {
    yaw_cos_sin_.emplace_back(std::cos(boxes_[b].yaw), std::sin(boxes_[b].yaw));
    all_boxes_.push_back(static_cast<int>(b));
  }

  // One texture per face, each from its own stream: changing one box leaves the others alone.
  const double metres_per_texel = 1.0 / config_.texels_per_metre;
  for (size_t b = 0; b < boxes_.size(); ++b) {
    for (int face = 0; face < 6; ++face) {
      int ua, va;
      faceAxes(face, &ua, &va);
      const Eigen::Vector3d& h = boxes_[b].half_size;
      const int w =
          std::max(4, static_cast<int>(std::ceil(2.0 * h[ua] * config_.texels_per_metre)));
      const int ht =
          std::max(4, static_cast<int>(std::ceil(2.0 * h[va] * config_.texels_per_metre)));
      FaceTexture t;
      t.levels.push_back(makeTexture(w, ht, metres_per_texel, streamSeed(seed, 100 + b, face)));
      while (std::min(t.levels.back().cols, t.levels.back().rows) >= 4) {
        cv::Mat down;
        cv::pyrDown(t.levels.back(), down);
        t.levels.push_back(down);
      }
      textures_.push_back(std::move(t));
    }
  }
}

std::optional<SurfaceHit> SyntheticScene::castRay(const Eigen::Vector3d& origin,
                                                  const Eigen::Vector3d& direction,
                                                  double max_t) const {
  return castRay(origin, direction, max_t, all_boxes_);
}

std::vector<int> SyntheticScene::boxesInView(const core::CameraPose& pose,
                                             const core::PinholeIntrinsics& k) const {
  // Inward normals of the frustum's side planes in camera coordinates, half a pixel outside the
  // image, and the plane z = 0 (a box behind the camera cannot be seen).
  const double left = (-0.5 - k.cx) / k.fx, right = (k.width - 0.5 - k.cx) / k.fx;
  const double top = (-0.5 - k.cy) / k.fy, bottom = (k.height - 0.5 - k.cy) / k.fy;
  const Eigen::Vector3d planes[5] = {
      Eigen::Vector3d(1.0, 0.0, -left).normalized(), Eigen::Vector3d(-1.0, 0.0, right).normalized(),
      Eigen::Vector3d(0.0, 1.0, -top).normalized(), Eigen::Vector3d(0.0, -1.0, bottom).normalized(),
      Eigen::Vector3d(0.0, 0.0, 1.0)};
  std::vector<int> in_view;
  for (size_t b = 0; b < boxes_.size(); ++b) {
    const Eigen::Vector3d c = pose.worldToCamera(boxes_[b].centre);
    const double radius = boxes_[b].half_size.norm();
    bool visible = boxes_[b].inside;  // the room surrounds the camera
    if (!visible) {
      visible = true;
      for (const Eigen::Vector3d& n : planes) visible = visible && n.dot(c) >= -radius;
    }
    if (visible) in_view.push_back(static_cast<int>(b));
  }
  return in_view;
}

std::optional<SurfaceHit> SyntheticScene::castRay(const Eigen::Vector3d& origin,
                                                  const Eigen::Vector3d& direction, double max_t,
                                                  const std::vector<int>& among) const {
  double best_t = max_t;
  int best_box = -1, best_face = -1;
  for (const int id : among) {
    if (id < 0 || id >= static_cast<int>(boxes_.size())) {
      throw core::InvalidArgument("SyntheticScene::castRay: no box " + std::to_string(id));
    }
    const size_t b = static_cast<size_t>(id);
    const SceneBox& box = boxes_[b];
    const Yaw yaw(yaw_cos_sin_[b]);
    const Eigen::Vector3d o = yaw.toLocal(origin - box.centre);
    const Eigen::Vector3d d = yaw.toLocal(direction);
    double t_near = -std::numeric_limits<double>::infinity();
    double t_far = std::numeric_limits<double>::infinity();
    int near_face = -1, far_face = -1;
    bool miss = false;
    for (int a = 0; a < 3 && !miss; ++a) {
      const double h = box.half_size[a];
      if (d[a] == 0.0) {
        miss = o[a] < -h || o[a] > h;
        continue;
      }
      const double inv = 1.0 / d[a];
      double t0 = (-h - o[a]) * inv, t1 = (h - o[a]) * inv;
      int f0 = 2 * a, f1 = 2 * a + 1;  // faces met at t0 and t1
      if (t0 > t1) {
        std::swap(t0, t1);
        std::swap(f0, f1);
      }
      if (t0 > t_near) {
        t_near = t0;
        near_face = f0;
      }
      if (t1 < t_far) {
        t_far = t1;
        far_face = f1;
      }
      miss = t_near > t_far;
    }
    if (miss) continue;
    if (t_near > 0.0 && t_near <= best_t) {
      best_t = t_near;
      best_box = static_cast<int>(b);
      best_face = near_face;
    } else if (t_near <= 0.0 && t_far > 0.0 && t_far <= best_t) {
      best_t = t_far;
      best_box = static_cast<int>(b);
      best_face = far_face;
    }
  }
  if (best_box < 0) return std::nullopt;

  const SceneBox& box = boxes_[static_cast<size_t>(best_box)];
  const Yaw yaw(yaw_cos_sin_[static_cast<size_t>(best_box)]);
  SurfaceHit hit;
  hit.t = best_t;
  hit.point = origin + best_t * direction;
  hit.box = best_box;
  hit.face = best_face;
  const int axis = best_face / 2;
  Eigen::Vector3d n_local = Eigen::Vector3d::Zero();
  n_local[axis] = best_face % 2 == 1 ? 1.0 : -1.0;
  Eigen::Vector3d n = yaw.toWorld(n_local);
  if (n.dot(direction) > 0.0) n = -n;  // face the viewer (inside the room, outside an object)
  hit.normal = n;
  const Eigen::Vector3d local = yaw.toLocal(hit.point - box.centre);
  int ua, va;
  faceAxes(best_face, &ua, &va);
  hit.uv = Eigen::Vector2d(std::clamp(local[ua] + box.half_size[ua], 0.0, 2.0 * box.half_size[ua]),
                           std::clamp(local[va] + box.half_size[va], 0.0, 2.0 * box.half_size[va]));
  return hit;
}

double SyntheticScene::distanceToSurface(const Eigen::Vector3d& p) const {
  double best = std::numeric_limits<double>::infinity();
  for (size_t b = 0; b < boxes_.size(); ++b) {
    const Eigen::Vector3d local = Yaw(yaw_cos_sin_[b]).toLocal(p - boxes_[b].centre);
    best = std::min(best, std::abs(signedBoxDistance(local, boxes_[b].half_size)));
  }
  return best;
}

bool SyntheticScene::isFree(const Eigen::Vector3d& p, double margin) const {
  for (size_t b = 0; b < boxes_.size(); ++b) {
    const SceneBox& box = boxes_[b];
    const double sd =
        signedBoxDistance(Yaw(yaw_cos_sin_[b]).toLocal(p - box.centre), box.half_size);
    if (box.inside ? sd > -margin : sd < margin) return false;
  }
  return true;
}

Eigen::Vector3f SyntheticScene::albedo(const SurfaceHit& hit, double footprint) const {
  if (hit.box < 0 || hit.box >= static_cast<int>(boxes_.size()) || hit.face < 0 || hit.face > 5) {
    throw core::InvalidArgument("SyntheticScene::albedo: the hit names no face of this scene");
  }
  const FaceTexture& tex = texture(hit.box, hit.face);
  const double texels = std::max(footprint, 0.0) * config_.texels_per_metre;
  const double level = std::clamp(texels > 1.0 ? std::log2(texels) : 0.0, 0.0,
                                  static_cast<double>(tex.levels.size() - 1));
  auto sample = [&](int l) {
    const cv::Mat& img = tex.levels[static_cast<size_t>(l)];
    const double scale = config_.texels_per_metre / std::ldexp(1.0, l);
    // Texel centres at integer + 0.5; clamp to the edge.
    const double x = std::clamp(hit.uv.x() * scale - 0.5, 0.0, img.cols - 1.0);
    const double y = std::clamp(hit.uv.y() * scale - 0.5, 0.0, img.rows - 1.0);
    const int x0 = std::min(static_cast<int>(x), img.cols - 2 < 0 ? 0 : img.cols - 2);
    const int y0 = std::min(static_cast<int>(y), img.rows - 2 < 0 ? 0 : img.rows - 2);
    const int x1 = std::min(x0 + 1, img.cols - 1), y1 = std::min(y0 + 1, img.rows - 1);
    const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
    const cv::Vec3b& a = img.at<cv::Vec3b>(y0, x0);
    const cv::Vec3b& b = img.at<cv::Vec3b>(y0, x1);
    const cv::Vec3b& c = img.at<cv::Vec3b>(y1, x0);
    const cv::Vec3b& d = img.at<cv::Vec3b>(y1, x1);
    Eigen::Vector3f out;
    for (int ch = 0; ch < 3; ++ch) {
      const float top = a[ch] + fx * (b[ch] - a[ch]);
      const float bottom = c[ch] + fx * (d[ch] - c[ch]);
      out[ch] = (top + fy * (bottom - top)) * (1.0f / 255.0f);
    }
    return out;
  };
  const int l0 = static_cast<int>(level);
  const float w = static_cast<float>(level - l0);
  const Eigen::Vector3f c0 = sample(l0);
  if (w <= 0.0f || l0 + 1 >= static_cast<int>(tex.levels.size())) return c0;
  return c0 + w * (sample(l0 + 1) - c0);
}

}  // namespace view_selection::sim
