// Deterministic random numbers for the simulator. Everything random in the simulated world and sensor is
// a pure function of integer keys (seed, cell, frame, ray, ...), mixed with the SplitMix64 finaliser.
// Standard-library distributions are never used: their output differs between library implementations,
// and the same seed must give the same bytes everywhere.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>

namespace sglc::sim {

inline constexpr std::uint64_t kGolden = 0x9E3779B97F4A7C15ULL;

// SplitMix64 output function: a bijection on 64-bit integers with good avalanche.
inline constexpr std::uint64_t finalizeBits(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

inline constexpr std::uint64_t mix64(std::uint64_t x) { return finalizeBits(x + kGolden); }

// Order-sensitive hash of several integer keys (signed values are reinterpreted, so -1 and 2^64-1 collide,
// which no caller relies on).
template <class... Keys>
inline constexpr std::uint64_t hashKeys(std::uint64_t first, Keys... rest) {
  std::uint64_t h = mix64(first);
  ((h = mix64(h ^ static_cast<std::uint64_t>(rest))), ...);
  return h;
}

// Uniform double in [0, 1) from the top 53 bits.
inline double unitFromBits(std::uint64_t bits) { return static_cast<double>(bits >> 11) * 0x1.0p-53; }

// Standard normal from one 64-bit hash (Box-Muller on its two 32-bit halves).
inline double normalFromBits(std::uint64_t bits) {
  const double u1 = (static_cast<double>(bits >> 32) + 1.0) * 0x1.0p-32;  // (0, 1]
  const double u2 = static_cast<double>(bits & 0xFFFFFFFFULL) * 0x1.0p-32;
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

// Cheap approximately normal value (zero mean, unit variance, bounded at +-3.46) from one 64-bit hash: the
// sum of four 16-bit uniforms (Irwin-Hall), rescaled. Used per ray, where log/cos would dominate the cost.
inline float approxNormalFromBits(std::uint64_t bits) {
  float sum = 0.0f;
  for (int k = 0; k < 4; ++k) sum += static_cast<float>((bits >> (16 * k)) & 0xFFFFu);
  return (sum * (1.0f / 65536.0f) + 4.0f * (0.5f / 65536.0f) - 2.0f) * 1.7320508f;
}

// Sequential generator (SplitMix64 stream), used where draws happen in a fixed order.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    state_ += kGolden;
    return finalizeBits(state_);
  }
  double unit() { return unitFromBits(next()); }
  double uniform(double lo, double hi) { return lo + (hi - lo) * unit(); }
  double normal() { return normalFromBits(next()); }
  bool chance(double p) { return unit() < p; }
  // Integer in [0, n), n > 0.
  int below(int n) { return static_cast<int>(((next() >> 32) * static_cast<std::uint64_t>(n)) >> 32); }

 private:
  std::uint64_t state_;
};

}  // namespace sglc::sim
