// The procedural world: determinism, street layout, ground, moving agents.
#include "sim_test_util.hpp"

namespace sglc::sim::test {
namespace {

const World& loopWorld() {
  static const World w(loopTrajectory().poses, 7);
  return w;
}

TEST(World, SameSeedSameWorldOtherSeedOtherWorld) {
  const World again(loopTrajectory().poses, 7);
  EXPECT_EQ(again.contentHash(), loopWorld().contentHash());
  EXPECT_EQ(again.statics().size(), loopWorld().statics().size());
  const World other(loopTrajectory().poses, 8);
  EXPECT_NE(other.contentHash(), loopWorld().contentHash());
  // Not just a relabelling: the objects are elsewhere.
  std::set<std::pair<long, long>> a, b;
  for (const auto& p : loopWorld().statics()) a.insert({std::lround(p.cx), std::lround(p.cy)});
  for (const auto& p : other.statics()) b.insert({std::lround(p.cx), std::lround(p.cy)});
  std::vector<std::pair<long, long>> common;
  std::set_intersection(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(common));
  EXPECT_LT(common.size(), a.size() / 4);
}

TEST(World, HasEveryKindOfObject) {
  const auto& s = loopWorld().stats();
  EXPECT_GT(s.buildings, 20u);
  EXPECT_GT(s.trees, 30u);
  EXPECT_GT(s.poles, 20u);
  EXPECT_GT(s.signs, 5u);
  EXPECT_GT(s.parked_vehicles, 50u);
  EXPECT_GT(s.moving_agents, 5u);
  std::set<std::uint32_t> classes;
  for (const auto& p : loopWorld().statics()) classes.insert(label::classOf(p.label));
  for (std::uint32_t c :
       {label::kCar, label::kBuilding, label::kVegetation, label::kTrunk, label::kPole, label::kTrafficSign})
    EXPECT_TRUE(classes.count(c)) << "class " << c;
  const auto& st = loopWorld().style();
  EXPECT_GE(st.lane_width, 3.0);
  EXPECT_LE(st.lane_width, 3.6);
  EXPECT_GT(st.lotLine(), st.kerb());
  EXPECT_GT(st.kerb(), st.road_half_width);
}

TEST(World, NothingStandsOnTheRoad) {
  const World& w = loopWorld();
  const auto& st = w.style();
  for (const auto& p : w.statics()) {
    const std::uint32_t cls = label::classOf(p.label);
    const double d = w.roadDistance(p.cx, p.cy);
    if (cls == label::kVegetation && p.shape == Shape::kEllipsoid) continue;  // canopies overhang the street
    if (cls == label::kPole && p.shape == Shape::kBox) continue;              // lamp arms reach over it
    if (cls == label::kCar || cls == label::kTruck || cls == label::kOtherVehicle)
      EXPECT_GE(d, st.road_half_width + 0.4) << "vehicle at " << p.cx << ", " << p.cy;
    else if (cls == label::kBuilding)
      EXPECT_GE(d, st.lotLine()) << "building at " << p.cx << ", " << p.cy;
    else
      EXPECT_GE(d, st.kerb()) << "class " << cls << " at " << p.cx << ", " << p.cy;
  }
}

TEST(World, GroundFollowsTheTrajectory) {
  const auto& t = loopTrajectory();
  const World& w = loopWorld();
  double worst = 0;
  for (std::size_t k = 0; k < t.poses.size(); k += 10) {
    const Vec3d p = t.poses[k].topRightCorner<3, 1>();
    worst = std::max(worst, std::abs(p.z() - w.groundHeight(p.x(), p.y()) - 1.73));
    EXPECT_EQ(w.groundLabel(p.x(), p.y()), label::kRoad);
  }
  EXPECT_LT(worst, 0.15);
}

TEST(World, KittiGroundFollowsItsSlopes) {
  SGLC_REQUIRE_KITTI("00");
  const auto& t = kittiSequence("00");
  const World w(t.poses, 7);
  std::vector<double> residual;
  double zmin = 1e9, zmax = -1e9;
  for (std::size_t k = 0; k < t.poses.size(); k += 10) {
    const Vec3d p = t.poses[k].topRightCorner<3, 1>();
    residual.push_back(std::abs(p.z() - w.groundHeight(p.x(), p.y()) - 1.73));
    zmin = std::min(zmin, p.z());
    zmax = std::max(zmax, p.z());
  }
  std::sort(residual.begin(), residual.end());
  EXPECT_GT(zmax - zmin, 10.0);  // KITTI 00 climbs about 20 m
  // KITTI's heights disagree by up to ~1 m where a street is driven twice; the ground takes the middle.
  EXPECT_LT(residual[residual.size() / 2], 0.2);
  EXPECT_LT(residual.back(), 1.0);
}

TEST(World, MovingAgentsAreAFunctionOfTime) {
  const World& w = loopWorld();
  std::vector<Primitive> a, b, c;
  w.movingNear(12.3, 100, 0, 1e6, a);
  w.movingNear(12.3, 100, 0, 1e6, b);
  w.movingNear(12.4, 100, 0, 1e6, c);
  ASSERT_FALSE(a.empty());
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(a.size(), c.size());
  int moved = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].cx, b[k].cx);
    EXPECT_EQ(a[k].cy, b[k].cy);
    moved += std::hypot(a[k].cx - c[k].cx, a[k].cy - c[k].cy) > 0.05;
    const std::uint32_t cls = label::classOf(a[k].label);
    EXPECT_GE(cls, 252u);  // moving classes only
    if (cls != label::kMovingPerson) {
      EXPECT_LT(w.roadDistance(a[k].cx, a[k].cy), w.style().road_half_width);
    }
  }
  EXPECT_GT(moved, static_cast<int>(a.size()) / 2);
}

}  // namespace
}  // namespace sglc::sim::test
