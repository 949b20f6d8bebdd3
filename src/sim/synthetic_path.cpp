// The handheld-like camera path of the synthetic sequence.
#include "synthetic_random.h"
#include "view_selection/core/exceptions.h"
#include "view_selection/sim/synthetic_sequence.h"

#include <cmath>

namespace view_selection::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// A sum of sines with seeded phases: smooth, bounded, never periodic over a sequence.
struct Sway {
  struct Term {
    double amplitude, frequency, phase;
  };
  std::vector<Term> terms;
  double operator()(double t) const {
    double v = 0.0;
    for (const Term& term : terms)
      v += term.amplitude * std::sin(2.0 * kPi * term.frequency * t + term.phase);
    return v;
  }
};

Sway sway(synthetic::Rng& rng,
          std::initializer_list<std::pair<double, double>> amplitude_frequency) {
  Sway s;
  for (const auto& [a, f] : amplitude_frequency) {
    // Frequencies vary a little with the seed too, so two seeds do not sway in lockstep.
    s.terms.push_back({a, f * rng.uniform(0.85, 1.15), rng.uniform(0.0, 2.0 * kPi)});
  }
  return s;
}

/// A unit quaternion that Eigen's normalize() leaves unchanged bit for bit, so a pose written
/// exactly and read back (the reader normalises) is the same pose. qw >= 0.
Eigen::Quaterniond stableUnit(const Eigen::Matrix3d& r) {
  Eigen::Quaterniond q(r);
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  q.normalize();
  auto stable = [](const Eigen::Quaterniond& c) { return c.normalized().coeffs() == c.coeffs(); };
  if (stable(q)) return q;
  // Normalising can flip between two neighbours forever; a nudge of a unit in the last place
  // of one coefficient finds a representation whose squared norm rounds to exactly 1.
  for (int ulps = 1; ulps <= 4; ++ulps) {
    for (int i = 0; i < 4; ++i) {
      for (const double direction : {1.0, -1.0}) {
        Eigen::Quaterniond c = q;
        double& v = c.coeffs()[i];
        for (int k = 0; k < ulps; ++k) v = std::nextafter(v, direction * 2.0);
        if (stable(c)) return c;
      }
    }
  }
  return q;  // not reached in practice; the reader's normalisation then moves the last bit
}

}  // namespace

std::vector<io::TumPoseEntry> syntheticCameraPath(const SyntheticSequenceConfig& config) {
  config.validate();
  synthetic::Rng rng(synthetic::streamSeed(config.seed, 2));
  const Eigen::Vector3d room = config.scene.room_size;
  // The loop: an ellipse around the middle, far enough from the walls to see them whole.
  const double a = 0.2 * room.x(), b = 0.18 * room.y();
  const double height = std::min(1.45, 0.5 * room.z());

  double theta = rng.uniform(0.0, 2.0 * kPi);
  // Slow sways (a person walking, turning to look), then a hand's fast small jitter.
  const Sway sx = sway(rng, {{0.10, 0.13}, {0.05, 0.37}, {0.003, 1.7}, {0.002, 2.9}});
  const Sway sy = sway(rng, {{0.10, 0.11}, {0.05, 0.41}, {0.003, 1.9}, {0.002, 3.1}});
  const Sway sz = sway(rng, {{0.06, 0.21}, {0.02, 0.53}, {0.003, 2.3}, {0.002, 3.7}});
  const Sway yaw_sway = sway(rng, {{0.45, 0.09}, {0.12, 0.27}, {0.004, 2.3}, {0.003, 4.1}});
  const Sway pitch_sway = sway(rng, {{0.12, 0.17}, {0.04, 0.45}, {0.004, 2.7}, {0.003, 3.9}});
  const Sway roll_sway = sway(rng, {{0.05, 0.23}, {0.003, 2.1}, {0.002, 3.3}});
  const double pitch_down = 0.26;  // look about 15 degrees down: walls, objects and some floor

  std::vector<io::TumPoseEntry> path;
  path.reserve(static_cast<size_t>(config.frames));
  const int substeps = 16;
  const double dt = 1.0 / config.fps;
  for (int i = 0; i < config.frames; ++i) {
    if (i > 0) {
      // Walk at `speed` along the ellipse: d(theta)/dt = speed / |dp/dtheta|.
      for (int k = 0; k < substeps; ++k) {
        const double tangent = std::hypot(a * std::sin(theta), b * std::cos(theta));
        theta += config.speed / tangent * dt / substeps;
      }
    }
    const double t = i * dt;
    const Eigen::Vector3d position(a * std::cos(theta) + sx(t), b * std::sin(theta) + sy(t),
                                   height + sz(t));
    // Mostly outwards (the ellipse's normal), towards the walls and what stands there.
    const double outwards = std::atan2(std::sin(theta) / b, std::cos(theta) / a);
    const double yaw = outwards + yaw_sway(t);
    const double pitch = pitch_down + pitch_sway(t);
    const double roll = roll_sway(t);

    const Eigen::Vector3d forward(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw),
                                  -std::sin(pitch));
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    const Eigen::Vector3d down = forward.cross(right);
    Eigen::Matrix3d r;
    r.col(0) = right;
    r.col(1) = down;
    r.col(2) = forward;
    r = r * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix();

    io::TumPoseEntry entry;
    // Whole microseconds: the 6-decimal stamps of rgb.txt then read back as the same doubles.
    entry.stamp = std::round((config.start_stamp + t) * 1e6) / 1e6;
    entry.pose.position = position;
    entry.pose.orientation = stableUnit(r);
    path.push_back(entry);
  }
  return path;
}

std::vector<io::TumPoseEntry> syntheticRingPath(const SyntheticSequenceConfig& config,
                                                const Eigen::Vector3d& target) {
  config.validate();
  std::vector<io::TumPoseEntry> path;
  const double elevation = config.ring_elevation_deg * kPi / 180.0;
  for (int i = 0; i < config.frames; ++i) {
    const double azimuth = i * config.ring_step_deg * kPi / 180.0;
    const Eigen::Vector3d from_target(std::cos(elevation) * std::cos(azimuth),
                                      std::cos(elevation) * std::sin(azimuth),
                                      std::sin(elevation));
    const Eigen::Vector3d forward = -from_target;
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    Eigen::Matrix3d r;
    r.col(0) = right;
    r.col(1) = forward.cross(right);
    r.col(2) = forward;
    io::TumPoseEntry entry;
    entry.stamp = std::round((config.start_stamp + i / config.fps) * 1e6) / 1e6;
    entry.pose.position = target + config.ring_distance * from_target;
    entry.pose.orientation = stableUnit(r);
    path.push_back(entry);
  }
  return path;
}

}  // namespace view_selection::sim
