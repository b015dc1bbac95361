#include "sglc/labels.hpp"

#include <string>

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
}

}  // namespace sglc
