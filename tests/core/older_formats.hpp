// Fingerprint blobs of the formats before the current one, as older builds wrote them, for the tests of
// reading and migrating them. Format 4 added a flags byte after `background_max_z`; format 3 added two fields
// to the layout: the spectrum's `orders` (u16, after `rings`) and `background_max_z` (f32, after
// `plane_voxel`); formats 1 and 2 share one layout and differ in how their scan descriptor was made.
#pragma once

#include <zlib.h>

#include <cstdint>
#include <cstring>
#include <vector>

#include "sglc/fingerprint.hpp"

namespace sglc::test {

// `fp` serialised in format `version` (1, 2 or 3) with `descriptor` as its stored scan descriptor. The layout
// of formats 1 and 2 has `rings` count the ring key's rings: 2 * rings values, as many as the current spectrum's.
inline std::vector<std::uint8_t> olderFormatBlob(const Fingerprint& fp, std::uint32_t version,
                                                 const std::vector<float>& descriptor) {
  auto b = serialize(fp);
  constexpr std::size_t kRings = 16 + 5, kOrders = kRings + 2, kMaxZ = kOrders + 2 + 16, kFlags = kMaxZ + 4;
  b.erase(b.begin() + kFlags);
  if (version < 3) {
    b.erase(b.begin() + kMaxZ, b.begin() + kMaxZ + 4);
    b.erase(b.begin() + kOrders, b.begin() + kOrders + 2);
    const auto rings = static_cast<std::uint16_t>(fp.layout.spectrumDim() / 2);
    std::memcpy(b.data() + kRings, &rings, 2);
  }
  std::memcpy(b.data() + b.size() - 4 * descriptor.size(), descriptor.data(), 4 * descriptor.size());
  const auto payload = static_cast<std::uint32_t>(b.size() - 16);
  const auto crc = static_cast<std::uint32_t>(crc32(0L, b.data() + 16, payload));
  std::memcpy(b.data() + 4, &version, 4);
  std::memcpy(b.data() + 8, &payload, 4);
  std::memcpy(b.data() + 12, &crc, 4);
  return b;
}

inline std::vector<std::uint8_t> olderFormatBlob(const Fingerprint& fp, std::uint32_t version) {
  return olderFormatBlob(fp, version, fp.descriptor);
}

}  // namespace sglc::test
