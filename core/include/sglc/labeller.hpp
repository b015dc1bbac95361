// A built-in scene labeller for raw LiDAR (x, y, z only): each point gets one of the roles the engine uses.
//
// Loop closing needs labels that are repeatable more than correct: the same street must cluster into the same
// objects on every visit. The labeller is geometric, deterministic and O(N), and assumes no beam model, ring
// index or sensor height, so it serves 16 to 128 beams, non-repetitive patterns and downsampled clouds:
//  1. Ground: per 2 m column, the second-lowest point is the column's floor (robust to one stray return) and the
//     points within `ground_band_m` of it fit a plane (tilted up to 30 %, so slopes stay ground). A column whose
//     plane stands more than `ground_max_step_m` above the planes of two neighbours (where the columns meet) has
//     no ground of its own (a car, a bush, a wall's foot): its plane is fitted from the lowest floor of its 3 x 3
//     neighbourhood instead. Points within `ground_tolerance_m` of the plane are ground (road role).
//  2. Objects: points between `ground_tolerance_m` and `low_band_m` above the ground (the band where trunks,
//     poles, cars, walls and hedges all appear, below canopies) are binned into `cell_m` columns; 8-connected
//     columns are objects, classified by their footprint (principal extents), height and what stands above:
//     thin and tall -> pole-like (trunk when a canopy spreads above it, else pole); car-sized, touching the
//     ground, nothing above 2.6 m -> vehicle; long and thin and tall -> building (wall); long, thin and low ->
//     fence; anything else -> vegetation.
//  3. Points above the band take their column's role (walls and fences rise into buildings, poles into poles,
//     car roofs up to vehicle_max_height_m stay vehicle); everything else above it is vegetation (canopy,
//     overhangs).
// Labels are written as the reserved ids below, which every LabelMap knows, so nothing downstream changes.
#pragma once

#include <cstdint>
#include <vector>

#include "sglc/config.hpp"
#include "sglc/types.hpp"

namespace sglc {

// Reserved label ids the labeller writes (low 16 bits); LabelMap maps them to roles in every configuration.
namespace labeller_ids {
inline constexpr std::uint32_t kNone = 0xFF00;  // beyond range or below the ground: ignored
inline constexpr std::uint32_t kGround = 0xFF01;
inline constexpr std::uint32_t kVegetation = 0xFF02;
inline constexpr std::uint32_t kBuilding = 0xFF03;
inline constexpr std::uint32_t kFence = 0xFF04;
inline constexpr std::uint32_t kVehicle = 0xFF10;
inline constexpr std::uint32_t kTrunk = 0xFF11;
inline constexpr std::uint32_t kPole = 0xFF12;
inline bool isReserved(std::uint32_t label) { return (label & 0xFF00u) == 0xFF00u && (label & 0xFFFFu) <= 0xFF12u; }
}  // namespace labeller_ids

// One reserved id per point (labeller_ids). Deterministic; throws nothing for finite input (non-finite points
// get kNone).
std::vector<std::uint32_t> labelScene(const Points& points, const LabellerConfig& config);

}  // namespace sglc
