// Maps raw label ids to the roles the engine uses (node class, background class, ignored).
#pragma once

#include <cstdint>
#include <vector>

#include "sglc/config.hpp"

namespace sglc {

// Background classes, numbered by priority in the background agreement grid: a cell holding several classes
// takes the structure class with most votes, ties going to the higher number (class_votes.hpp), and road only
// where no structure is seen.
enum class Background : std::uint8_t { kNone = 0, kRoad = 1, kVegetation = 2, kBuilding = 3, kFence = 4 };

class LabelMap {
 public:
  explicit LabelMap(const LabelConfig& config);

  // Index into config.node_classes, or -1. Moving classes are never node classes.
  int nodeClass(std::uint32_t label) const { return role_[label & 0xFFFFu] >= 0 ? role_[label & 0xFFFFu] : -1; }
  Background background(std::uint32_t label) const {
    const int r = role_[label & 0xFFFFu];
    return r <= -2 ? static_cast<Background>(-r - 1) : Background::kNone;
  }
  // Raw role code, for hot loops that need both answers: >= 0 node class, -1 ignored, <= -2 background
  // (Background value = -code - 1).
  int role(std::uint32_t label) const { return role_[label & 0xFFFFu]; }
  int numNodeClasses() const { return num_node_classes_; }
  // Whether the configured ids cover these landmark roles (a label set without them, like nuScenes-lidarseg's
  // without poles and trunks, is completed by the labeller in "auto" mode).
  bool hasVehicleIds() const { return has_vehicle_ids_; }
  bool hasTrunkIds() const { return has_trunk_ids_; }
  bool hasPoleIds() const { return has_pole_ids_; }

 private:
  // >= 0: node class index; -1: ignored; <= -2: background class (-role - 1).
  std::vector<std::int8_t> role_;
  int num_node_classes_ = 0;
  bool has_vehicle_ids_ = false, has_trunk_ids_ = false, has_pole_ids_ = false;
};

}  // namespace sglc
