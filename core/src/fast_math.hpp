// Internal numeric helpers for the hot loops.
#pragma once

#include <cmath>
#include <numbers>

namespace sglc::detail {

// atan2 with a maximum error of about 1e-5 rad (degree-11 minimax polynomial for atan on [0, 1]).
// Several times faster than std::atan2, and deterministic.
inline float fastAtan2(float y, float x) {
  const float ax = std::fabs(x), ay = std::fabs(y);
  const float mx = ax > ay ? ax : ay;
  if (mx == 0.0f) return 0.0f;
  const float z = (ax > ay ? ay : ax) / mx;
  const float z2 = z * z;
  float r =
      z * (0.99997726f +
           z2 * (-0.33262347f + z2 * (0.19354346f + z2 * (-0.11643287f + z2 * (0.05265332f + z2 * -0.01172120f)))));
  if (ay > ax) r = std::numbers::pi_v<float> / 2 - r;
  if (x < 0) r = std::numbers::pi_v<float> - r;
  return y < 0 ? -r : r;
}

// floor() to int for values well inside the int range; compiles to a few integer ops without SSE4.1.
inline int floorInt(float v) {
  const int i = static_cast<int>(v);
  return i - (v < static_cast<float>(i));
}

// Snaps a coordinate to the 1 cm grid that fingerprints store exactly.
inline float snapCm(float v) { return static_cast<float>(std::lround(v * 100.0f)) / 100.0f; }

}  // namespace sglc::detail
