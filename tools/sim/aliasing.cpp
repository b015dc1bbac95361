#include "sim/aliasing.hpp"

#include "sim/rng.hpp"

namespace sglc::sim {
namespace {
constexpr std::uint64_t kAliasStream = 0xA11A5ULL;
}

std::uint64_t lotTemplateKey(std::uint64_t seed, int side, int index, int district, double rate) {
  if (rate <= 0.0) return 0;
  const std::uint64_t h =
      hashKeys(seed, kAliasStream, static_cast<std::uint64_t>(side + 2), static_cast<std::uint64_t>(index));
  // One uniform per lot, compared with the rate: the aliased set only grows with the rate.
  if (unitFromBits(h) >= rate) return 0;
  const auto id = static_cast<std::uint64_t>(((mix64(h) >> 32) * kTemplatesPerDistrict) >> 32);
  return hashKeys(seed, kAliasStream, 0x7E3B1A7EULL, static_cast<std::uint64_t>(district), id) | 1u;
}

}  // namespace sglc::sim
