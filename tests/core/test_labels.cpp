// LabelMap: raw SemanticKITTI ids -> node class / background role.
#include <gtest/gtest.h>

#include "sglc/labels.hpp"
#include "sglc/types.hpp"

namespace sglc {
namespace {

TEST(Labels, DefaultMap) {
  const LabelMap m{LabelConfig{}};
  EXPECT_EQ(m.numNodeClasses(), 3);
  // Node classes: vehicle 0 (car 10, truck 18, other-vehicle 20), trunk 1, pole 2.
  EXPECT_EQ(m.nodeClass(10), 0);
  EXPECT_EQ(m.nodeClass(18), 0);
  EXPECT_EQ(m.nodeClass(20), 0);
  EXPECT_EQ(m.nodeClass(71), 1);
  EXPECT_EQ(m.nodeClass(80), 2);
  for (std::uint32_t id : {10u, 18u, 20u, 71u, 80u}) EXPECT_EQ(m.background(id), Background::kNone) << id;
  // Background classes.
  EXPECT_EQ(m.background(40), Background::kRoad);
  EXPECT_EQ(m.background(50), Background::kBuilding);
  EXPECT_EQ(m.background(51), Background::kFence);
  EXPECT_EQ(m.background(70), Background::kVegetation);
  for (std::uint32_t id : {40u, 50u, 51u, 70u}) EXPECT_EQ(m.nodeClass(id), -1) << id;
  // Everything else is ignored: unlabelled 0, outlier 1, sidewalk 48, traffic-sign 81, other-object 99.
  for (std::uint32_t id : {0u, 1u, 48u, 52u, 60u, 81u, 99u, 65535u}) {
    EXPECT_EQ(m.nodeClass(id), -1) << id;
    EXPECT_EQ(m.background(id), Background::kNone) << id;
  }
}

TEST(Labels, RoleAgreesWithNodeClassAndBackground) {
  LabelConfig cfg;
  cfg.road.push_back(252);  // moving: ignored whatever the lists say
  const LabelMap m{cfg};
  for (std::uint32_t id = 0; id < 300; ++id) {
    for (std::uint32_t inst : {0u, 9u << 16}) {
      const std::uint32_t label = inst | id;
      const int role = m.role(label);
      if (role >= 0) {
        EXPECT_EQ(m.nodeClass(label), role) << id;
        EXPECT_EQ(m.background(label), Background::kNone) << id;
      } else if (role == -1) {
        EXPECT_EQ(m.nodeClass(label), -1) << id;
        EXPECT_EQ(m.background(label), Background::kNone) << id;
      } else {
        EXPECT_EQ(m.nodeClass(label), -1) << id;
        EXPECT_EQ(static_cast<int>(m.background(label)), -role - 1) << id;
      }
    }
  }
  EXPECT_EQ(m.role(80), 2);
  EXPECT_EQ(m.role(40), -2);  // road: Background 1
  EXPECT_EQ(m.role(51), -5);  // fence: Background 4
  EXPECT_EQ(m.role(252), -1);
}

TEST(Labels, BackgroundPriorityOrder) {
  // The BEV grid keeps the highest: fence > building > vegetation > road.
  EXPECT_GT(static_cast<int>(Background::kFence), static_cast<int>(Background::kBuilding));
  EXPECT_GT(static_cast<int>(Background::kBuilding), static_cast<int>(Background::kVegetation));
  EXPECT_GT(static_cast<int>(Background::kVegetation), static_cast<int>(Background::kRoad));
  EXPECT_GT(static_cast<int>(Background::kRoad), static_cast<int>(Background::kNone));
}

TEST(Labels, InstanceBitsIgnored) {
  const LabelMap m{LabelConfig{}};
  for (std::uint32_t inst : {1u, 7u, 0x1234u, 0xFFFFu}) {
    const std::uint32_t hi = inst << 16;
    EXPECT_EQ(m.nodeClass(hi | 10u), 0);
    EXPECT_EQ(m.nodeClass(hi | 71u), 1);
    EXPECT_EQ(m.nodeClass(hi | 80u), 2);
    EXPECT_EQ(m.background(hi | 40u), Background::kRoad);
    EXPECT_EQ(m.background(hi | 51u), Background::kFence);
    EXPECT_EQ(m.nodeClass(hi | 0u), -1);
    EXPECT_EQ(m.nodeClass(hi | 252u), -1);
  }
}

TEST(Labels, MovingNeverNodeOrBackground) {
  const LabelMap def{LabelConfig{}};
  for (std::uint32_t id = 252; id <= 259; ++id) {
    EXPECT_EQ(def.nodeClass(id), -1) << id;
    EXPECT_EQ(def.background(id), Background::kNone) << id;
  }
  // Even when a configuration lists moving ids as a node class or background.
  LabelConfig cfg;
  cfg.node_classes = {{"vehicle", {10, 252, 256}}, {"pole", {80, 258}}};
  cfg.road = {40, 253};
  const LabelMap m{cfg};
  EXPECT_EQ(m.numNodeClasses(), 2);
  EXPECT_EQ(m.nodeClass(10), 0);
  EXPECT_EQ(m.nodeClass(80), 1);
  for (std::uint32_t id : {252u, 253u, 256u, 258u}) {
    EXPECT_EQ(m.nodeClass(id), -1) << id;
    EXPECT_EQ(m.background(id), Background::kNone) << id;
  }
  EXPECT_EQ(m.background(40), Background::kRoad);
}

TEST(Labels, IdWithTwoRolesRejected) {
  {
    LabelConfig cfg;
    cfg.node_classes = {{"vehicle", {10}}, {"pole", {80, 10}}};  // 10 in two node classes
    EXPECT_THROW(LabelMap{cfg}, InputError);
  }
  {
    LabelConfig cfg;
    cfg.building = {50, 40};  // 40 is road too
    EXPECT_THROW(LabelMap{cfg}, InputError);
  }
  {
    LabelConfig cfg;
    cfg.node_classes[2].ids.push_back(70);  // 70 is vegetation
    try {
      LabelMap m{cfg};
      ADD_FAILURE() << "expected InputError";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("70"), std::string::npos) << e.what();
    }
  }
}

TEST(Labels, InvalidClassCountOrIdRejected) {
  LabelConfig cfg;
  cfg.node_classes.clear();
  EXPECT_THROW(LabelMap{cfg}, InputError);
  cfg.node_classes.assign(17, {"x", {}});
  EXPECT_THROW(LabelMap{cfg}, InputError);
  LabelConfig big;
  big.road = {70000};
  EXPECT_THROW(LabelMap{big}, InputError);
}

TEST(Labels, CustomLabelSet) {
  LabelConfig cfg;
  cfg.node_classes = {{"a", {1}}, {"b", {2}}};
  cfg.road = {3};
  cfg.building = {4};
  cfg.fence = {};
  cfg.vegetation = {5, 6};
  const LabelMap m{cfg};
  EXPECT_EQ(m.numNodeClasses(), 2);
  EXPECT_EQ(m.nodeClass(1), 0);
  EXPECT_EQ(m.nodeClass(2), 1);
  EXPECT_EQ(m.nodeClass(3), -1);
  EXPECT_EQ(m.background(3), Background::kRoad);
  EXPECT_EQ(m.background(4), Background::kBuilding);
  EXPECT_EQ(m.background(5), Background::kVegetation);
  EXPECT_EQ(m.background(6), Background::kVegetation);
  // The default ids mean nothing in this set.
  for (std::uint32_t id : {10u, 40u, 50u, 51u, 70u, 71u, 80u}) {
    EXPECT_EQ(m.nodeClass(id), -1) << id;
    EXPECT_EQ(m.background(id), Background::kNone) << id;
  }
}

}  // namespace
}  // namespace sglc
