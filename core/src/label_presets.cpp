// The label presets: SemanticKITTI raw ids (LabelConfig's defaults), its 19 training ids, nuScenes-lidarseg.
#include "sglc/config.hpp"

#include "sglc/types.hpp"

namespace sglc {

const std::vector<std::string>& labelPresetNames() {
  static const std::vector<std::string> names{"semantickitti", "semantickitti-train", "nuscenes"};
  return names;
}

LabelConfig labelPreset(const std::string& name) {
  LabelConfig c;  // SemanticKITTI raw ids
  c.preset = name;
  if (name == "semantickitti") return c;
  if (name == "semantickitti-train") {
    // SemanticKITTI's learning map (19 classes): 1 car, 4 truck, 5 other-vehicle, 9 road, 13 building,
    // 14 fence, 15 vegetation, 16 trunk, 18 pole; moving objects are merged into their static classes.
    c.node_classes = {{"vehicle", {1, 4, 5}}, {"trunk", {16}}, {"pole", {18}}};
    c.road = {9};
    c.building = {13};
    c.fence = {14};
    c.vegetation = {15};
    c.moving = {};
    return c;
  }
  if (name == "nuscenes") {
    // nuScenes-lidarseg (32 classes): vehicles 15-20, 22, 23 (bus, car, construction, emergency, trailer,
    // truck); 24 driveable surface; 28 static.manmade; 9 barrier; 30 vegetation. No pole or trunk class: they
    // are part of manmade and vegetation, and the labeller fills them in "auto" mode.
    c.node_classes = {{"vehicle", {15, 16, 17, 18, 19, 20, 22, 23}}, {"trunk", {}}, {"pole", {}}};
    c.road = {24};
    c.building = {28};
    c.fence = {9};
    c.vegetation = {30};
    c.moving = {};
    return c;
  }
  std::string known;
  for (const auto& n : labelPresetNames()) known += (known.empty() ? "" : ", ") + n;
  throw InputError("labels.preset: unknown preset '" + name + "' (known: " + known + ")");
}

}  // namespace sglc
