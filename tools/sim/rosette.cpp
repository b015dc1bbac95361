// The ray pattern of a non-repetitive rosette scanner (Livox-Avia-like).
//
// A pair of Risley prisms spinning in opposite directions at different speeds steers the beam along
// (e^{i(k+1)phi} + e^{-i(k-1)phi}) / 2 = cos(k phi) e^{i phi}: a rose curve (rhodonea). With an irrational
// petal ratio k the curve never closes, so every frame (the next 100 ms of the same curve) covers new gaps
// and the coverage of a still scene keeps growing with integration time, as with the real sensor.
#include <algorithm>
#include <cmath>
#include <numbers>

#include "sim/rng.hpp"
#include "sim/sensor.hpp"

namespace sglc::sim {
namespace {

const double kPetalRatio = std::sqrt(5.0);  // irrational: the rose never repeats
constexpr double kTurnsPerFrame = 13.7;     // prism turns per frame: about 60 petal passes per frame

}  // namespace

void rosetteRays(const SensorConfig& sensor, std::uint64_t seed, int index, std::vector<RosetteRay>& out) {
  const int rays = sensor.rosette_rays, rows = sensor.beams(), cols = sensor.columns;
  const int channels = std::max(1, sensor.rosette_channels);
  constexpr double kDeg = std::numbers::pi / 180.0;
  const double half_h = 0.5 * sensor.rosette_fov_h_deg * kDeg, half_v = 0.5 * sensor.rosette_fov_v_deg * kDeg;
  // The unit's starting phase comes from the seed; then the curve runs on continuously through the frames.
  const double phase0 = 2.0 * std::numbers::pi * unitFromBits(hashKeys(seed, 0x2053ULL));
  out.resize(static_cast<std::size_t>(std::max(0, rays)));
  for (int k = 0; k < rays; ++k) {
    const double tau = index + (k + 0.5) / rays;  // time in frames
    const double phi = 2.0 * std::numbers::pi * kTurnsPerFrame * tau + phase0;
    const double r = std::cos(kPetalRatio * phi);
    const double x = r * std::cos(phi), y = r * std::sin(phi);  // inside the unit disc
    RosetteRay& ray = out[k];
    ray.azimuth = static_cast<float>(half_h * x);
    ray.elevation = static_cast<float>(half_v * y);
    ray.channel = static_cast<std::uint16_t>(k % channels);
    ray.row = static_cast<std::uint16_t>(std::clamp(static_cast<int>((1.0 - y) * 0.5 * rows), 0, rows - 1));
    ray.column = static_cast<std::uint16_t>(std::clamp(static_cast<int>((x + 1.0) * 0.5 * cols), 0, cols - 1));
  }
}

}  // namespace sglc::sim
