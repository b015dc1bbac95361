// Time in the simulated world (--epoch, --turnover): parked vehicles come and go, temporary objects appear
// and vanish, foliage follows the season; and look-alike streets (--aliasing).
#include <cstdio>

#include "sim/occupancy.hpp"
#include "sim_test_util.hpp"

namespace sglc::sim::test {
namespace {

WorldConfig turnoverConfig(int epoch = 0) {
  WorldConfig c;
  c.turnover = true;
  c.epoch = epoch;
  return c;
}

const World& frozenWorld() {
  static const World w(loopTrajectory().poses, 7);
  return w;
}
const World& turnoverWorld() {
  static const World w(loopTrajectory().poses, 7, turnoverConfig());
  return w;
}

bool isVehicle(const Primitive& p) {
  const auto c = label::classOf(p.label);
  return c == label::kCar || c == label::kTruck || c == label::kOtherVehicle;
}

// Parked vehicles (one entry per vehicle: its presence key) of a world with turnover present at time t.
std::set<std::uint32_t> parkedAt(const World& w, double t) {
  std::set<std::uint32_t> out;
  for (const auto& p : w.statics())
    if (p.presence != 0 && isVehicle(p) && w.present(p, t)) out.insert(p.presence);
  return out;
}

// Share of the vehicles parked at t0 that are gone (or replaced) at t1.
double changedShare(const World& w, double t0, double t1) {
  const auto a = parkedAt(w, t0), b = parkedAt(w, t1);
  std::size_t gone = 0;
  for (auto k : a) gone += !b.contains(k);
  return a.empty() ? 0.0 : static_cast<double>(gone) / a.size();
}

TEST(Time, FrozenByDefault) {
  // Without turnover the epoch changes nothing, not even the foliage: day 200 is today's world.
  WorldConfig winter_off;
  winter_off.epoch = 200;
  const World off(loopTrajectory().poses, 7, winter_off);
  EXPECT_EQ(off.contentHash(), frozenWorld().contentHash());
  EXPECT_DOUBLE_EQ(off.absoluteTime(12.5), 12.5);
  for (const auto& p : frozenWorld().statics()) ASSERT_EQ(p.presence, 0u);
  EXPECT_NE(turnoverWorld().contentHash(), frozenWorld().contentHash());
  EXPECT_DOUBLE_EQ(frozenWorld().absoluteTime(12.5), 12.5);
  EXPECT_DOUBLE_EQ(World(loopTrajectory().poses, 7, turnoverConfig(3)).absoluteTime(12.5), 3 * 86400 + 12.5);
}

TEST(Time, BadConfigIsRefused) {
  WorldConfig c = turnoverConfig(-1);
  EXPECT_THROW(World(loopTrajectory().poses, 7, c), InputError);
  c = WorldConfig{};
  c.aliasing = 1.5;
  EXPECT_THROW(World(loopTrajectory().poses, 7, c), InputError);
}

TEST(Time, DayZeroStartsWithTodaysParkedVehicles) {
  // Today's parked vehicles (their boxes) and the ones present at t = 0 of epoch 0 are mostly the same.
  auto boxes = [](const World& w, bool timed) {
    std::set<std::pair<long, long>> out;
    for (const auto& p : w.statics())
      if (isVehicle(p) && (!timed || w.present(p, 0.0))) out.insert({std::lround(p.cx * 10), std::lround(p.cy * 10)});
    return out;
  };
  const auto today = boxes(frozenWorld(), false), zero = boxes(turnoverWorld(), true);
  std::size_t kept = 0;
  for (const auto& b : today) kept += zero.contains(b);
  std::printf("today's parked vehicle boxes kept at epoch 0, t = 0: %zu of %zu (%zu present)\n", kept, today.size(),
              zero.size());
  EXPECT_GT(kept, today.size() * 8 / 10);
}

TEST(Time, ParkedVehiclesChangeOverMinutesDaysAndMonths) {
  const World& w = turnoverWorld();
  ASSERT_GT(parkedAt(w, 0).size(), 80u);
  const double minutes = changedShare(w, 0, 120), day = changedShare(w, 0, 86400),
               season = changedShare(w, 0, 90 * 86400.0);
  std::printf("parked vehicles changed: 2 min %.3f, 1 day %.3f, 90 days %.3f\n", minutes, day, season);
  EXPECT_GT(minutes, 0.01);
  EXPECT_LT(minutes, 0.12);
  EXPECT_GT(day, 0.35);
  EXPECT_LT(day, 0.65);
  EXPECT_GT(season, 0.75);
}

TEST(Time, FewParkedVehiclesChangeBetweenAVisitAndTheRevisit) {
  // For each parked vehicle seen (within 20 m) at a first visit and again more than 20 s later on the route.
  const World& w = turnoverWorld();
  const auto& poses = loopTrajectory().poses;
  const double dt = loopTrajectory().frame_dt;
  std::size_t seen = 0, changed = 0;
  double gap_sum = 0;
  std::set<std::uint32_t> done;
  for (const auto& p : w.statics()) {
    if (p.presence == 0 || !isVehicle(p) || !done.insert(p.presence).second) continue;
    int first = -1, again = -1;
    for (int i = 0; i < static_cast<int>(poses.size()); ++i) {
      if (std::hypot(poses[i](0, 3) - p.cx, poses[i](1, 3) - p.cy) > 20) continue;
      if (first < 0) first = i;
      if ((i - first) * dt > 20) {
        again = i;
        break;
      }
    }
    if (again < 0 || !w.present(p, first * dt)) continue;
    ++seen;
    gap_sum += (again - first) * dt;
    changed += !w.present(p, again * dt);
  }
  const double share = static_cast<double>(changed) / std::max<std::size_t>(seen, 1);
  std::printf("revisited parked vehicles changed: %zu of %zu (%.3f), mean gap %.0f s\n", changed, seen, share,
              gap_sum / std::max<std::size_t>(seen, 1));
  ASSERT_GT(seen, 30u);
  EXPECT_GT(share, 0.01);
  EXPECT_LT(share, 0.15);
}

TEST(Time, TemporaryObjectsComeAndGoWithTheEpoch) {
  const World& w = turnoverWorld();
  const auto& st = w.stats();
  ASSERT_GT(st.temporary_sites, 5u);
  // Sites: timed primitives that are not parked vehicles, or trucks outside the slots' vehicles... count by
  // presence key over the labels temporary objects use, and the epochs at which each is there.
  std::map<std::uint32_t, int> days_present;
  std::set<std::uint32_t> sites;
  for (const auto& p : w.statics()) {
    const auto c = label::classOf(p.label);
    if (p.presence == 0 || (c != label::kFence && c != label::kOtherObject)) continue;
    sites.insert(p.presence);
    for (int day = 0; day < 120; ++day) days_present[p.presence] += w.present(p, day * 86400.0);
  }
  ASSERT_GT(sites.size(), 3u);
  int sometimes = 0, total = 0;
  for (const auto& [key, n] : days_present) {
    sometimes += n > 0 && n < 120;
    total += n;
  }
  const double per_km = (static_cast<double>(total) / 120) * (1000.0 / st.path_length_m);
  std::printf("temporary sites %zu (fences/skips %zu), fences/skips present per km of street: %.2f\n",
              st.temporary_sites, sites.size(), per_km);
  EXPECT_GE(sometimes, static_cast<int>(sites.size()) * 8 / 10);
  EXPECT_GT(per_km, 0.5);
  EXPECT_LT(per_km, 10.0);
}

TEST(Time, FoliageIsSparserInWinterWithTheSameTrunks) {
  const World winter(loopTrajectory().poses, 7, turnoverConfig(182));
  const auto &a = turnoverWorld().statics(), &b = winter.statics();
  ASSERT_EQ(a.size(), b.size());
  int sparser = 0, crowns = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (label::classOf(a[i].label) == label::kTrunk) {
      EXPECT_EQ(a[i].cx, b[i].cx);
      EXPECT_EQ(a[i].z1, b[i].z1);
    }
    if (label::classOf(a[i].label) != label::kVegetation) continue;
    ++crowns;
    sparser += b[i].pass_through > a[i].pass_through + 20;
    EXPECT_EQ(a[i].hx, b[i].hx);
  }
  ASSERT_GT(crowns, 50);
  EXPECT_EQ(sparser, crowns);
  // Day 0 is summer: today's porosity.
  std::multiset<int> today, day0;
  for (const auto& p : frozenWorld().statics())
    if (label::classOf(p.label) == label::kVegetation) today.insert(p.pass_through);
  for (const auto& p : a)
    if (label::classOf(p.label) == label::kVegetation && p.presence == 0) day0.insert(p.pass_through);
  EXPECT_EQ(today, day0);
}

TEST(Time, SameSeedAndEpochSameFrameOtherEpochOtherParkedCars) {
  SimConfig cfg = smallConfig();
  cfg.world = turnoverConfig(1);
  const Simulator a(loopTrajectory(), cfg), b(loopTrajectory(), cfg);
  const Frame fa = a.render(150), fb = b.render(150);
  EXPECT_EQ(fa.scan.points, fb.scan.points);
  EXPECT_EQ(fa.scan.labels, fb.scan.labels);
  cfg.world.epoch = 0;
  const Simulator c(loopTrajectory(), cfg);
  int differing = 0;
  for (int index : {100, 150, 400, 700}) {
    const Frame f1 = a.render(index), f0 = c.render(index);
    differing += f1.scan.labels != f0.scan.labels;
  }
  EXPECT_GE(differing, 3);
}

World aliasedWorld(double rate) {
  WorldConfig c;
  c.aliasing = rate;
  return World(loopTrajectory().poses, 7, c);
}

// Pairs of buildings more than 40 m apart with the same footprint and height above their base: copies of
// one template (independent draws practically never agree to the last bit).
int lookAlikeBuildingPairs(const World& w) {
  std::vector<const Primitive*> b;
  for (const auto& p : w.statics())
    if (label::classOf(p.label) == label::kBuilding) b.push_back(&p);
  int pairs = 0;
  for (std::size_t i = 0; i < b.size(); ++i)
    for (std::size_t j = i + 1; j < b.size(); ++j)
      pairs += std::hypot(b[i]->cx - b[j]->cx, b[i]->cy - b[j]->cy) > 40 && b[i]->hy == b[j]->hy &&
               b[i]->reflectivity == b[j]->reflectivity;
  return pairs;
}

TEST(Aliasing, ZeroIsTodaysWorldAndMoreRepeatsMoreTemplates) {
  // A rate so small that no lot draws a template leaves every lot, and so the whole world, as it was: only the
  // lots that are copies change.
  EXPECT_EQ(aliasedWorld(1e-12).stats().aliased_lots, 0u);
  EXPECT_EQ(aliasedWorld(1e-12).contentHash(), frozenWorld().contentHash());
  EXPECT_EQ(lookAlikeBuildingPairs(frozenWorld()), 0);
  const World half = aliasedWorld(0.5), all = aliasedWorld(1.0);
  const int p_half = lookAlikeBuildingPairs(half), p_all = lookAlikeBuildingPairs(all);
  std::printf("look-alike lots: R=0.5 %zu, R=1 %zu; look-alike building pairs: R=0.5 %d, R=1 %d (buildings %zu)\n",
              half.stats().aliased_lots, all.stats().aliased_lots, p_half, p_all, all.stats().buildings);
  EXPECT_GT(half.stats().aliased_lots, 0u);
  EXPECT_GT(all.stats().aliased_lots, half.stats().aliased_lots);
  EXPECT_GT(p_half, 5);
  EXPECT_GT(p_all, p_half);
  EXPECT_GT(all.stats().buildings, 40u);  // the templates still make a city, not an empty street
}

}  // namespace
}  // namespace sglc::sim::test
