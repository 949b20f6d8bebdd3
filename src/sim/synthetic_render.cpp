// Rendering the synthetic sequence by ray casting: colour with simple shading and seeded noise,
// z-depth in TUM units.
#include "synthetic_random.h"
#include "view_selection/core/exceptions.h"
#include "view_selection/sim/synthetic_sequence.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace view_selection::sim {
namespace {

constexpr double kDepthUnitsPerMetre = 5000.0;  // TUM depth PNGs

}  // namespace

core::PinholeIntrinsics syntheticIntrinsics(int width, int height) {
  core::PinholeIntrinsics k;
  k.fx = k.fy = 525.0 * width / 640.0;
  k.cx = (width - 1) / 2.0;
  k.cy = (height - 1) / 2.0;
  k.width = width;
  k.height = height;
  return k;
}

void SyntheticSequenceConfig::validate() const {
  std::ostringstream msg;
  if (frames < 1 || frames > 1000000) {
    msg << "frames = " << frames << " must be 1..1000000";
  } else if (!intrinsics.isValid() || !std::isfinite(intrinsics.cx) ||
             !std::isfinite(intrinsics.cy)) {
    msg << "the intrinsics are invalid (focal lengths and image size must be positive)";
  } else if (intrinsics.width < 8 || intrinsics.height < 8 || intrinsics.width > 8192 ||
             intrinsics.height > 8192) {
    msg << "image size " << intrinsics.width << "x" << intrinsics.height
        << " must be 8..8192 pixels each way";
  } else if (!(fps > 0.0 && fps <= 1000.0)) {
    msg << "fps = " << fps << " must be in (0, 1000]";
  } else if (!(speed >= 0.0 && speed <= 10.0)) {
    msg << "speed = " << speed << " m/s must be 0..10";
  } else if (!(std::isfinite(start_stamp) && start_stamp >= 0.0 && start_stamp <= 1e10)) {
    msg << "start_stamp = " << start_stamp << " s must be 0..1e10";
  } else if (!(noise_sigma >= 0.0 && noise_sigma <= 50.0)) {
    msg << "noise_sigma = " << noise_sigma << " must be 0..50 grey levels";
  } else if (!(max_range > 0.0 && max_range <= 65535.0 / kDepthUnitsPerMetre)) {
    msg << "max_range = " << max_range << " m must be in (0, 13.107] (16-bit depth at 5000/m)";
  } else if (!(ring_step_deg >= 0.0 && ring_step_deg <= 360.0) ||
             !(ring_distance > 0.0 && ring_distance <= 10.0) ||
             !(ring_elevation_deg > -90.0 && ring_elevation_deg < 90.0)) {
    msg << "ring: step " << ring_step_deg << " deg must be 0..360, distance " << ring_distance
        << " m in (0, 10], elevation " << ring_elevation_deg << " deg in (-90, 90)";
  } else if (!(unit_scale > 0.0 && std::isfinite(unit_scale))) {
    msg << "unit_scale = " << unit_scale << " must be positive";
  } else if (unit_scale != 1.0 && write_depth) {
    msg << "unit_scale " << unit_scale << " needs no depth (depth PNGs hold 5000 units a metre)";
  } else {
    scene.validate();
    return;
  }
  throw core::InvalidArgument("synthetic sequence: " + msg.str());
}

namespace {
/// Validates before the scene's textures are built: a bad option fails at once.
const SyntheticSequenceConfig& validated(const SyntheticSequenceConfig& config) {
  config.validate();
  return config;
}
/// The centre of the box on the table (the room's centre at table height without a table).
Eigen::Vector3d ringTarget(const SyntheticScene& scene) {
  for (const SceneBox& b : scene.boxes())
    if (b.name == "box on table") return b.centre;
  return Eigen::Vector3d(0.0, 0.0, 0.8);
}
}  // namespace

SyntheticSequence::SyntheticSequence(const SyntheticSequenceConfig& config)
    : config_(validated(config)),
      scene_(config.seed, config.scene),
      path_(config.ring_step_deg > 0.0 ? syntheticRingPath(config, ringTarget(scene_))
                                       : syntheticCameraPath(config)) {
  for (const io::TumPoseEntry& e : path_) {
    if (!scene_.isFree(e.pose.position, 0.2)) {
      throw core::InvalidArgument(
          "synthetic sequence: the camera path comes within 0.2 m of a surface; use a larger "
          "room or fewer objects");
    }
  }
}

SyntheticFrame SyntheticSequence::render(size_t index) const {
  if (index >= path_.size()) {
    throw core::InvalidArgument("synthetic sequence: frame " + std::to_string(index) +
                                " does not exist (" + std::to_string(path_.size()) + " frames)");
  }
  const core::PinholeIntrinsics& k = config_.intrinsics;
  SyntheticFrame frame;
  frame.stamp = path_[index].stamp;
  frame.pose = path_[index].pose;
  frame.colour.create(k.height, k.width, CV_8UC3);
  frame.depth.create(k.height, k.width, CV_16UC1);

  const Eigen::Matrix3d r = frame.pose.rotation();
  const Eigen::Vector3d origin = frame.pose.position;
  const Eigen::Vector3d room = config_.scene.room_size;
  // One light under the ceiling, a little off the middle, plus ambient light.
  const Eigen::Vector3d light(0.15 * room.x(), -0.1 * room.y(), room.z() - 0.3);
  const double focal = std::sqrt(k.fx * k.fy);
  const double far = 4.0 * room.norm();  // the colour camera sees every wall; depth stops earlier
  const uint64_t noise_seed = synthetic::streamSeed(config_.seed, 3, index);
  const float sigma = static_cast<float>(config_.noise_sigma);
  const std::vector<int> in_view = scene_.boxesInView(frame.pose, k);

  for (int v = 0; v < k.height; ++v) {
    cv::Vec3b* colour_row = frame.colour.ptr<cv::Vec3b>(v);
    uint16_t* depth_row = frame.depth.ptr<uint16_t>(v);
    for (int u = 0; u < k.width; ++u) {
      // Through the pixel's centre (integer coordinates, as PinholeIntrinsics::project gives);
      // the camera ray has z = 1, so the ray parameter t is the z-depth.
      const Eigen::Vector3d ray = r * k.backProject(Eigen::Vector2d(u, v));
      const std::optional<SurfaceHit> hit = scene_.castRay(origin, ray, far, in_view);
      Eigen::Vector3f c = Eigen::Vector3f::Zero();
      uint16_t depth = 0;
      if (hit) {
        if (hit->t <= config_.max_range) {
          depth = static_cast<uint16_t>(std::lround(hit->t * kDepthUnitsPerMetre));
        }
        const double range = hit->t * ray.norm();
        const double cosine = std::abs(hit->normal.dot(ray)) / ray.norm();
        // One pixel's size on the surface; a slanted surface stretches it (geometric mean).
        const double footprint = range / focal / std::sqrt(std::max(cosine, 0.02));
        const Eigen::Vector3d to_light = light - hit->point;
        const double d2 = to_light.squaredNorm();
        const double lambert = std::max(0.0, hit->normal.dot(to_light) / std::sqrt(d2));
        const float shade = static_cast<float>(0.35 + 0.9 * lambert / (1.0 + 0.06 * d2));
        c = scene_.albedo(*hit, footprint) * shade;
      }
      cv::Vec3b& out = colour_row[u];
      uint64_t bits = sigma > 0.0f ? synthetic::mix64(noise_seed ^ (static_cast<uint64_t>(v) << 32 |
                                                                    static_cast<uint64_t>(u)))
                                   : 0;
      for (int ch = 0; ch < 3; ++ch) {
        float value = 255.0f * c[ch];
        if (sigma > 0.0f) {
          // Four 5-bit uniforms summed: near-Gaussian with unit variance after scaling.
          float sum = 0.0f;
          for (int q = 0; q < 4; ++q) {
            sum += static_cast<float>(bits & 31u) + 0.5f;
            bits >>= 5;
          }
          value += sigma * (sum / 32.0f - 2.0f) * 1.7320508f;
        }
        out[ch] = static_cast<uint8_t>(std::clamp(std::lround(value), 0L, 255L));
      }
      depth_row[u] = depth;
    }
  }
  return frame;
}

}  // namespace view_selection::sim
