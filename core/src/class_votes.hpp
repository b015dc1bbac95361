// The class of a background BEV cell from the votes of the points (or stored cells) falling in it; one rule
// for the stored BEV, its agreement score and the background search.
#pragma once

#include <array>
#include <cstdint>

#include "sglc/labels.hpp"

namespace sglc::detail {

// Votes of the background classes falling in one BEV cell. The cell's class is the structure class (fence,
// building, vegetation) with most votes, ties going to the higher priority, and road only where no structure
// is seen: a wall's cell also holds road at its foot. A majority rather than "any point of the highest
// priority" (the published code) keeps a cell's class when a segmentation network mislabels some of its
// points (a blob of fence on a facade, vegetation on a fence). Counts saturate at 255.
struct ClassVotes {
  std::array<std::uint8_t, 5> n{0, 0, 0, 0, 0};  // indexed by Background
  void add(Background b) {
    auto& v = n[static_cast<int>(b)];
    if (v < 0xFF) ++v;
  }
  std::uint8_t winner() const {
    int best = 0;
    for (int cls = static_cast<int>(Background::kFence); cls >= static_cast<int>(Background::kVegetation); --cls)
      if (n[cls] > (best ? n[best] : 0)) best = cls;
    if (best == 0 && n[static_cast<int>(Background::kRoad)] > 0) best = static_cast<int>(Background::kRoad);
    return static_cast<std::uint8_t>(best);
  }
};

}  // namespace sglc::detail
