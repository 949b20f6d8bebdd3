// Private to the synthetic sequence: a seeded generator whose numbers are the same with every
// compiler and standard library (std::*_distribution are implementation-defined, so unused), and
// a counter-based hash for per-pixel noise that does not depend on the order of rendering.
#pragma once

#include <cmath>
#include <cstdint>

namespace view_selection::synthetic {

/// splitmix64's finaliser: a bijective mix of 64 bits.
inline uint64_t mix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

/// A stream seed for (seed, a, b): independent streams for every texture, the path, the noise.
inline uint64_t streamSeed(uint64_t seed, uint64_t a, uint64_t b = 0) {
  return mix64(mix64(mix64(seed) ^ a) ^ (b * 0xD1B54A32D192ED03ull));
}

/// 53-bit uniform double in [0, 1) from 64 random bits.
inline double unitFromBits(uint64_t bits) {
  return static_cast<double>(bits >> 11) * (1.0 / 9007199254740992.0);
}

class Rng {
 public:
  explicit Rng(uint64_t seed) : state_(seed) {}
  uint64_t next() {
    state_ += 0x9E3779B97F4A7C15ull;
    uint64_t z = state_;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  /// Uniform in [lo, hi).
  double uniform(double lo = 0.0, double hi = 1.0) { return lo + (hi - lo) * unitFromBits(next()); }
  /// Log-uniform in [lo, hi), lo > 0: every scale equally likely.
  double logUniform(double lo, double hi) { return lo * std::exp(uniform() * std::log(hi / lo)); }
  /// Integer in [0, n).
  int below(int n) { return static_cast<int>(uniform() * n); }

 private:
  uint64_t state_;
};

}  // namespace view_selection::synthetic
