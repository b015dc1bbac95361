// Per-class IoU of noisy labels against the true ones, the way SemanticKITTI's single-scan benchmark scores a
// network: moving classes count as their static class, unlabelled/outlier/other-structure/other-object points
// are ignored, and a point predicted as an ignored class counts as a miss of its true class.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "sim/world.hpp"

namespace sglc::sim {

// The SemanticKITTI evaluation classes the simulator emits, in the benchmark's order.
inline constexpr int kEvalClasses = 15;
struct EvalClass {
  std::uint32_t id;  // raw SemanticKITTI id of the static class
  const char* name;  // as in the benchmark tables
};
inline constexpr std::array<EvalClass, kEvalClasses> kEvalClassTable = {{{label::kCar, "car"},
                                                                         {label::kTruck, "truck"},
                                                                         {label::kOtherVehicle, "other-vehicle"},
                                                                         {label::kPerson, "person"},
                                                                         {label::kRoad, "road"},
                                                                         {label::kParking, "parking"},
                                                                         {label::kSidewalk, "sidewalk"},
                                                                         {label::kOtherGround, "other-ground"},
                                                                         {label::kBuilding, "building"},
                                                                         {label::kFence, "fence"},
                                                                         {label::kVegetation, "vegetation"},
                                                                         {label::kTrunk, "trunk"},
                                                                         {label::kTerrain, "terrain"},
                                                                         {label::kPole, "pole"},
                                                                         {label::kTrafficSign, "traffic-sign"}}};

// Index into kEvalClassTable of a raw label (instance bits ignored, moving ids folded onto their static
// class), or -1 for a class the benchmark ignores or the simulator never emits.
int evalClassIndex(std::uint32_t raw_label);

// Confusion counts (true positives, false positives, false negatives per class) of predicted vs true labels.
class LabelIouCounts {
 public:
  // Both vectors hold one label per point, in the same order.
  void add(const std::vector<std::uint32_t>& truth, const std::vector<std::uint32_t>& predicted);
  // Labels that are their own truth (no label noise): every scored point is a true positive.
  void addExact(const std::vector<std::uint32_t>& labels);
  void merge(const LabelIouCounts& other);
  // A class is present when it occurs in the truth or in the prediction.
  bool present(int k) const { return tp_[k] + fp_[k] + fn_[k] > 0; }
  // tp / (tp + fp + fn); 0 for an absent class.
  double iou(int k) const;
  // Mean over the present classes (1 when none is present).
  double meanIou() const;
  std::uint64_t truthPoints(int k) const { return tp_[k] + fn_[k]; }

 private:
  std::array<std::uint64_t, kEvalClasses> tp_{}, fp_{}, fn_{};
};

}  // namespace sglc::sim
