// Mixed pixels: a laser footprint that straddles a depth edge returns one echo from both surfaces, and the
// sensor reports a range in between ("veil" or "comet" points between an object and what is behind it).
#include <cmath>

#include "sim/rng.hpp"
#include "sim/sensor.hpp"

namespace sglc::sim {

std::size_t applyMixedPixels(std::vector<float>& range, std::vector<Vec3f>& point, std::vector<std::uint32_t>& label,
                             std::vector<float>& intensity, std::size_t stride, bool wrap, double rate,
                             std::uint64_t key) {
  constexpr float kEdge = 1.0f;  // m: a smaller step is a slope, not an edge the footprint straddles
  const std::size_t n = range.size();
  if (rate <= 0.0 || n == 0 || stride == 0) return 0;
  const std::vector<float> r0(range);  // decide from the unmixed image, so the order of visits does not matter
  const std::vector<std::uint32_t> l0(label);
  const std::vector<float> i0(intensity);
  std::size_t mixed = 0;
  for (std::size_t px = 0; px < n; ++px) {
    if (r0[px] <= 0.0f) continue;
    // The neighbour across the larger depth step (a return with no echo beside it is not an edge here).
    std::size_t other = n;
    float step = kEdge;
    for (int side : {-1, 1}) {
      std::size_t q;
      if (side < 0) {
        if (px < stride && !wrap) continue;
        q = px >= stride ? px - stride : px + n - stride;
      } else {
        q = px + stride;
        if (q >= n) {
          if (!wrap) continue;
          q -= n;
        }
      }
      if (r0[q] > 0.0f && std::abs(r0[q] - r0[px]) > step) {
        step = std::abs(r0[q] - r0[px]);
        other = q;
      }
    }
    if (other == n) continue;
    const std::uint64_t h = hashKeys(key, 0x313DULL, px);
    if (unitFromBits(h) >= rate) continue;
    const float w = static_cast<float>(unitFromBits(mix64(h)));  // share of the echo from the other surface
    const float r = r0[px] + w * (r0[other] - r0[px]);
    point[px] *= r / r0[px];
    range[px] = r;
    if (r0[other] < r0[px]) label[px] = l0[other];
    intensity[px] = (1.0f - w) * i0[px] + w * i0[other];
    ++mixed;
  }
  return mixed;
}

}  // namespace sglc::sim
