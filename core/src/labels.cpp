#include "sglc/labels.hpp"

#include <string>

#include "sglc/labeller.hpp"
#include "sglc/types.hpp"

namespace sglc {

LabelMap::LabelMap(const LabelConfig& config) : role_(65536, -1) {
  if (config.node_classes.empty() || config.node_classes.size() > 16)
    throw InputError("labels: between 1 and 16 node classes are required, got " +
                     std::to_string(config.node_classes.size()));
  num_node_classes_ = static_cast<int>(config.node_classes.size());
  auto assign = [this](std::uint32_t id, int role, const std::string& what) {
    if (id > 0xFFFFu) throw InputError("labels: id " + std::to_string(id) + " in " + what + " exceeds 65535");
    if (role_[id] != -1)
      throw InputError("labels: id " + std::to_string(id) + " is given two roles (second: " + what + ")");
    role_[id] = static_cast<std::int8_t>(role);
  };
  // Background classes first, so that an id listed both as background and as a node class is reported.
  auto background = [&](const std::vector<std::uint32_t>& ids, Background b, const char* name) {
    for (auto id : ids) assign(id, -static_cast<int>(b) - 1, name);
  };
  background(config.road, Background::kRoad, "road");
  background(config.vegetation, Background::kVegetation, "vegetation");
  background(config.building, Background::kBuilding, "building");
  background(config.fence, Background::kFence, "fence");
  for (int c = 0; c < num_node_classes_; ++c)
    for (auto id : config.node_classes[c].ids) assign(id, c, "node class " + config.node_classes[c].name);
  // Moving objects are never landmarks nor background, whatever the lists above say.
  for (auto id : config.moving) {
    if (id > 0xFFFFu) throw InputError("labels: moving id " + std::to_string(id) + " exceeds 65535");
    role_[id] = -1;
  }
  // The labeller's reserved ids (sglc/labeller.hpp) mean the same in every configuration. Its landmark roles go
  // to the node classes of those names; without a "trunk" class trunks count as poles and the other way round,
  // and without either they are vegetation; without "vehicle", vehicles are ignored.
  auto nodeIndex = [&](const std::string& name) {
    for (int c = 0; c < num_node_classes_; ++c)
      if (config.node_classes[c].name == name) return c;
    return -1;
  };
  const int vehicle = nodeIndex("vehicle");
  int trunk = nodeIndex("trunk"), pole = nodeIndex("pole");
  if (trunk < 0) trunk = pole;
  if (pole < 0) pole = trunk;
  const int vegetation = -static_cast<int>(Background::kVegetation) - 1;
  role_[labeller_ids::kNone] = -1;
  role_[labeller_ids::kGround] = static_cast<std::int8_t>(-static_cast<int>(Background::kRoad) - 1);
  role_[labeller_ids::kVegetation] = static_cast<std::int8_t>(vegetation);
  role_[labeller_ids::kBuilding] = static_cast<std::int8_t>(-static_cast<int>(Background::kBuilding) - 1);
  role_[labeller_ids::kFence] = static_cast<std::int8_t>(-static_cast<int>(Background::kFence) - 1);
  role_[labeller_ids::kVehicle] = static_cast<std::int8_t>(vehicle);
  role_[labeller_ids::kTrunk] = static_cast<std::int8_t>(trunk >= 0 ? trunk : vegetation);
  role_[labeller_ids::kPole] = static_cast<std::int8_t>(pole >= 0 ? pole : vegetation);
  // Which roles the configured ids cover (the labeller fills the others in "auto" mode).
  has_vehicle_ids_ = vehicle >= 0 && !config.node_classes[vehicle].ids.empty();
  has_trunk_ids_ = nodeIndex("trunk") >= 0 && !config.node_classes[nodeIndex("trunk")].ids.empty();
  has_pole_ids_ = nodeIndex("pole") >= 0 && !config.node_classes[nodeIndex("pole")].ids.empty();
}

}  // namespace sglc
