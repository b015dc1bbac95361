// Time in the simulated world: which of a slot's candidate occupants is present at a given time, and how
// dense the foliage is in a given season. Everything is a pure function of integer keys and the time, so a
// frame stays a pure function of (seed, trajectory, configuration, frame index).
#pragma once

#include <cstdint>

namespace sglc::sim {

inline constexpr double kSecondsPerDay = 86400.0;

// One slot's occupancy over time: time is cut into intervals of `period` seconds (shifted by `phase`); in
// each interval the slot is empty (chance `empty`) or holds one of `candidates` occupants, drawn from a hash
// of (key, interval). The interval holding t = 0 may be pinned to a given occupant (today's world).
struct OccupancyProcess {
  std::uint64_t key = 0;
  double period = 1.0;  // s, how long one occupant stays
  double phase = 0.0;   // s, in [0, period)
  float empty = 0.0f;   // chance that an interval has no occupant
  std::uint8_t candidates = 1;
  std::int8_t at_zero = kDrawn;  // occupant in the interval holding t = 0: kEmpty, a candidate, or kDrawn

  static constexpr std::int8_t kEmpty = -1;
  static constexpr std::int8_t kDrawn = -2;
};

// The occupant at absolute time t (s): -1 when the slot is empty, else the candidate index.
int occupantAt(const OccupancyProcess& process, double t);

// Tuning of the kerb-side parking slots, lot bays and temporary objects (see tools/sim/README.md for the
// change shares these give).
struct TurnoverRates {
  double short_stay_share = 0.5;                    // share of parking slots used for short stays
  double short_stay_period = 600.0;                 // s: a short-stay occupant stays 10 minutes
  double resident_period = 5.7 * kSecondsPerDay;    // a resident's car stays 5.7 days
  int candidates = 3;                               // different vehicles that may use one slot
  double temporary_period = 10.0 * kSecondsPerDay;  // a skip or construction fence stays ~10 days
  double temporary_presence = 0.4;                  // chance that a temporary-object site is in use
};
inline constexpr TurnoverRates kTurnover{};

// A porous object's pass-through (x/255) on day `epoch`: `summer` in full leaf, `winter` bare.
std::uint8_t seasonalPassThrough(std::uint8_t summer, std::uint8_t winter, double epoch_days);

}  // namespace sglc::sim
