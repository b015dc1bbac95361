// The "network" label noise preset: errors shaped like a range-image segmentation network's, with one
// strength per class calibrated so that the per-class IoU of noisy vs true labels matches RangeNet53++'s
// published table (see kRangeNetIou). The shapes are fixed; only the per-class strengths are fitted
// (fitNetworkNoise below, run by tools/sim/fit_labels_main.cpp) and then frozen in NetworkNoiseParams::rangeNet().
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "sim/label_iou.hpp"
#include "sim/simulator.hpp"

namespace sglc::sim {

// RangeNet53++ with KNN post-processing on the SemanticKITTI single-scan test set, per-class IoU in %,
// mIoU 52.2 over all 19 classes: Milioto et al., "RangeNet++: Fast and Accurate LiDAR Semantic
// Segmentation", IROS 2019, Table II (the same row is reprinted in the SalsaNext paper's Table I and on the
// SemanticKITTI leaderboard). Only the 15 classes the simulator emits are kept (kEvalClassTable order); the
// others were bicycle 25.7, motorcycle 34.4, bicyclist 38.8, motorcyclist 4.8.
inline constexpr std::array<double, kEvalClasses> kRangeNetIou = {
    91.4,  // car
    25.7,  // truck
    23.0,  // other-vehicle
    38.3,  // person
    91.8,  // road
    65.0,  // parking
    75.2,  // sidewalk
    27.8,  // other-ground (never emitted by the simulator)
    87.4,  // building
    58.6,  // fence
    80.5,  // vegetation
    55.1,  // trunk
    64.6,  // terrain
    47.9,  // pole
    55.9,  // traffic-sign
};

struct NetworkNoiseParams {
  // Per evaluation class (kEvalClassTable order): the class's error strength. It scales the chance that a
  // blob of the class is relabelled, that its boundary pixels take a neighbour's label, and that one of its
  // instances is missed. Fitted.
  std::array<double, kEvalClasses> strength{};
  // Per class: how much of the error comes as whole missed instances (things only; 0 = never missed).
  std::array<double, kEvalClasses> miss_ratio{};
  // Error chance grows with range r as near_floor + (r / range_scale_m)^2 (blob relabelling) and
  // miss_near + (r / miss_range_m)^2 (missed instances).
  double near_floor = 0.35, range_scale_m = 25.0;
  double miss_near = 0.25, miss_range_m = 20.0;
  // Boundary bleed chance = min(bleed_cap, bleed_ratio * strength); a pixel two columns away leaks at half that.
  double bleed_ratio = 1.0, bleed_cap = 0.6;
  // Blobs: blob_beams rows x blob_columns columns of the range image share one decision per class (rows of
  // blobs are staggered like bricks, so blob edges do not line up).
  int blob_beams = 4, blob_columns = 16;

  // The frozen calibration (fitted on HDL-64 frames of the built-in route and of KITTI 00).
  static NetworkNoiseParams rangeNet();
};

// Applies the network model to a rendered frame in place (fills clean_labels). Deterministic in
// (seed, frame.index, labels, ranges).
// wrap as applyLabelNoise's.
void applyNetworkLabelNoise(Frame& frame, const NetworkNoiseParams& params, std::uint64_t seed, int beams, int columns,
                            bool wrap = true);

// IoU counts of the network model with `params` over frames rendered without label noise (their labels are
// the truth; the frames are left unchanged).
LabelIouCounts evaluateNetworkNoise(const std::vector<Frame>& clean_frames, const NetworkNoiseParams& params,
                                    std::uint64_t seed, int beams, int columns);

// The calibration: starting from `start`, adjusts each class's strength so that its IoU over `clean_frames`
// approaches kRangeNetIou (a damped multiplicative update of the error 1 - IoU, `iterations` rounds).
// `log` (optional) gets one line per round.
NetworkNoiseParams fitNetworkNoise(const std::vector<Frame>& clean_frames, NetworkNoiseParams start, std::uint64_t seed,
                                   int beams, int columns, int iterations,
                                   const std::function<void(const std::string&)>& log = {});

}  // namespace sglc::sim
