#include "sim/occupancy.hpp"

#include <cmath>
#include <numbers>

#include "sim/rng.hpp"

namespace sglc::sim {

int occupantAt(const OccupancyProcess& process, double t) {
  const auto interval = static_cast<std::int64_t>(std::floor((t + process.phase) / process.period));
  // With phase in [0, period), t = 0 falls in interval 0.
  if (interval == 0 && process.at_zero != OccupancyProcess::kDrawn) return process.at_zero;
  const std::uint64_t h = hashKeys(process.key, static_cast<std::uint64_t>(interval));
  if (unitFromBits(h) < process.empty) return -1;
  return static_cast<int>(((mix64(h) >> 32) * process.candidates) >> 32);
}

namespace {
// Leaf cover in [0, 1] on day `epoch`: 1 at epoch 0 (summer), 0 half a year later (winter), yearly cycle.
double leafCover(double epoch_days) { return 0.5 + 0.5 * std::cos(2.0 * std::numbers::pi * epoch_days / 365.25); }
}  // namespace

std::uint8_t seasonalPassThrough(std::uint8_t summer, std::uint8_t winter, double epoch_days) {
  const double leaf = leafCover(epoch_days);
  return static_cast<std::uint8_t>(std::lround(leaf * summer + (1.0 - leaf) * winter));
}

}  // namespace sglc::sim
