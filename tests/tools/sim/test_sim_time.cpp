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
  const World off(loopTrajectory().poses, 7, WorldConfig{});
  EXPECT_EQ(off.contentHash(), frozenWorld().contentHash());
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

}  // namespace
}  // namespace sglc::sim::test
