// Perceptual aliasing: look-alike streets. At rate R a lot copies its content from one of a few templates
// per district type (keyed by the template instead of the lot's own position), so that different places on
// the route look the same: same lot length, building size, setback and height, same yard and bays.
#pragma once

#include <cstdint>

namespace sglc::sim {

inline constexpr int kTemplatesPerDistrict = 3;

// The template key of lot `index` on `side` (-1 right, +1 left) in a district of type `district` when the lot
// copies a template at aliasing rate `rate`, else 0. A lot aliased at rate R is aliased at every rate above R.
std::uint64_t lotTemplateKey(std::uint64_t seed, int side, int index, int district, double rate);

}  // namespace sglc::sim
