// Label noise shaped like a segmentation network's mistakes, applied on the range image of a frame:
// missed small objects (they take the class of what surrounds them), boundary bleed (a label leaks one pixel
// across a class boundary), and class confusion in blobs (8 columns x 4 beams share one decision per class).
#include <algorithm>
#include <array>

#include "sim/label_noise_network.hpp"
#include "sim/point_image.hpp"
#include "sim/rng.hpp"
#include "sim/simulator.hpp"

namespace sglc::sim {
namespace {

bool isThing(std::uint32_t cls) {
  switch (cls) {
    case label::kCar:
    case label::kTruck:
    case label::kOtherVehicle:
    case label::kPerson:
    case label::kTrunk:
    case label::kPole:
    case label::kTrafficSign:
      return true;
    default:
      return cls >= 252 && cls <= 259;
  }
}

// Plausible confusions of a network, per class (0 terminates).
std::array<std::uint32_t, 3> confusions(std::uint32_t cls) {
  using namespace label;
  switch (cls) {
    case kCar:
      return {kTruck, kOtherVehicle, 0};
    case kTruck:
      return {kCar, kOtherVehicle, 0};
    case kOtherVehicle:
      return {kCar, kTruck, 0};
    case kRoad:
      return {kParking, kSidewalk, 0};
    case kParking:
      return {kRoad, kSidewalk, 0};
    case kSidewalk:
      return {kRoad, kParking, kTerrain};
    case kOtherGround:
      return {kSidewalk, kTerrain, 0};
    case kBuilding:
      return {kFence, kVegetation, 0};
    case kFence:
      return {kBuilding, kVegetation, 0};
    case kVegetation:
      return {kTerrain, kTrunk, kBuilding};
    case kTrunk:
      return {kVegetation, kPole, 0};
    case kTerrain:
      return {kVegetation, kSidewalk, 0};
    case kPole:
      return {kTrafficSign, kTrunk, kBuilding};
    case kTrafficSign:
      return {kPole, kBuilding, 0};
    case kPerson:
      return {kPole, kTrunk, 0};
    // A network without motion cues labels moving objects as their static class.
    case kMovingCar:
      return {kCar, 0, 0};
    case kMovingPerson:
      return {kPerson, 0, 0};
    case kMovingTruck:
      return {kTruck, 0, 0};
    case kMovingOtherVehicle:
      return {kOtherVehicle, 0, 0};
    default:
      return {0, 0, 0};
  }
}

std::uint32_t relabel(std::uint32_t raw, std::uint32_t cls) { return isThing(cls) ? (cls | (raw & 0xFFFF0000u)) : cls; }

}  // namespace

LabelNoise LabelNoise::fromRate(double rate) {
  LabelNoise n;
  n.confusion = rate;
  n.bleed = std::min(0.5, 2.0 * rate);
  n.miss = std::min(1.0, 2.0 * rate);
  return n;
}

LabelNoise LabelNoise::network() {
  LabelNoise n;
  n.model = LabelNoiseModel::kNetwork;
  return n;
}

void applyLabelNoise(Frame& frame, const LabelNoise& noise, std::uint64_t seed, int beams, int columns, bool wrap) {
  if (noise.model == LabelNoiseModel::kNetwork) {
    static const NetworkNoiseParams params = NetworkNoiseParams::rangeNet();
    applyNetworkLabelNoise(frame, params, seed, beams, columns, wrap);
    return;
  }
  auto& labels = frame.scan.labels;
  frame.clean_labels = labels;
  const std::size_t n = labels.size();
  if (n == 0) return;
  if (frame.beam.size() != n || frame.column.size() != n)
    throw InputError("label noise: the frame has no beam/column of its points");
  const std::uint64_t key = hashKeys(seed, 0x1AB1ULL, static_cast<std::uint64_t>(frame.index));
  const PointImage image(frame, beams, columns, wrap);
  auto at = [&](int b, int c) { return image.at(b, c); };

  // 1. Missed small objects take the class found beside them on the same beam.
  std::vector<std::uint32_t> step(labels);
  if (noise.miss > 0) {
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t raw = frame.clean_labels[i], cls = label::classOf(raw);
      if (cls != label::kPole && cls != label::kTrafficSign && cls != label::kTrunk) continue;
      if (unitFromBits(hashKeys(key, 1, raw)) >= noise.miss) continue;
      std::uint32_t replacement = label::kUnlabelled;
      for (int dc = 1; dc <= 25 && replacement == label::kUnlabelled; ++dc)
        for (int sgn : {-1, 1}) {
          const int j = at(frame.beam[i], frame.column[i] + sgn * dc);
          if (j < 0) continue;
          const std::uint32_t other = frame.clean_labels[j];
          const std::uint32_t oc = label::classOf(other);
          if (other == raw || oc == label::kPole || oc == label::kTrafficSign || oc == label::kTrunk) continue;
          replacement = oc;
          break;
        }
      step[i] = replacement;
    }
  }
  // 2. Boundary bleed: a point next to another class takes that neighbour's label.
  std::vector<std::uint32_t> bled(step);
  if (noise.bleed > 0) {
    for (std::size_t i = 0; i < n; ++i) {
      const int b = frame.beam[i], c = frame.column[i];
      const int nbr[4] = {at(b, c - 1), at(b, c + 1), at(b - 1, c), at(b + 1, c)};
      int candidates[4], k = 0;
      for (int j : nbr)
        if (j >= 0 && label::classOf(step[j]) != label::classOf(step[i])) candidates[k++] = j;
      if (k == 0) continue;
      const std::uint64_t h = hashKeys(key, 2, i);
      if (unitFromBits(h) >= noise.bleed) continue;
      bled[i] = step[candidates[(h & 0xFF) % k]];
    }
  }
  // 3. Confusion in blobs of 8 columns x 4 beams, decided per (blob, class).
  if (noise.confusion > 0) {
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t cls = label::classOf(bled[i]);
      const auto options = confusions(cls);
      int k = 0;
      while (k < 3 && options[k] != 0) ++k;
      if (k == 0) continue;
      const std::uint64_t h = hashKeys(key, 3, frame.beam[i] / 4, frame.column[i] / 8, cls);
      if (unitFromBits(h) >= noise.confusion) continue;
      bled[i] = relabel(bled[i], options[(h & 0xFF) % k]);
    }
  }
  labels.swap(bled);
}

}  // namespace sglc::sim
