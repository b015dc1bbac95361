// Lifelong maps (docs/LIFELONG.md): the place rule, and compaction on both back-ends: places for a map built
// before the policy, retirement of an ended session's surplus scans with their loops moved onto the scans of
// the session that stay (checked against the true relative poses), sessions within their retention left whole,
// surplus promoted where a place lost its versions, versions that no later visit chose replaced by the visit's scans
// (closing::rebalanceVersions on its own and through compaction), and nothing retired with the policy off.
#include <gtest/gtest.h>

#include <chrono>
#include <map>
#include <random>
#include <set>

#include "backend.hpp"
#include "sglc/closing/compaction.hpp"
#include "sglc/closing/places.hpp"
#include "sglc/closing/versions.hpp"

namespace sglc::closing {
namespace {

using storage::LoopRecord;
using storage::MapStore;
using storage::PlaceRecord;
using storage::testing::randomFingerprint;

// ---- The place rule, on its own.

struct FakeMap {
  std::map<std::int64_t, PlaceRecord> places;
  PlaceLookup lookup() {
    return {[this](std::int64_t id) -> std::optional<PlaceRecord> {
              const auto it = places.find(id);
              return it == places.end() ? std::nullopt : std::optional(it->second);
            },
            [this](std::int64_t place) {
              std::int64_t n = 0;
              for (const auto& [id, p] : places) n += p.place_id == place && p.kept;
              return n;
            }};
  }
  void add(const std::vector<PlaceRecord>& records) {
    for (const auto& r : records) places[r.scan_id] = r;
  }
};

LifelongOptions policy(int versions) {
  LifelongOptions o;
  o.max_versions_per_place = versions;
  o.place_radius_m = 3.0;
  o.min_probability = 0.9;
  o.session_retention_h = 0;
  return o;
}

TEST(PlaceRule, SurestCloseLoopJoinsAPlaceUntilItHoldsItsVersions) {
  FakeMap m;
  m.add(placeScan(1, {}, policy(2), m.lookup()));
  EXPECT_EQ(m.places[1].place_id, 1);  // no loop: founds its own place
  EXPECT_TRUE(m.places[1].kept);
  // Too unsure, too far, or of unknown probability: no tie.
  const auto alone = placeScan(2, {{1, 0.89, 0.5}, {1, 0.99, 3.5}, {1, std::nullopt, 0.1}}, policy(2), m.lookup());
  ASSERT_EQ(alone.size(), 1u);
  EXPECT_EQ(alone[0].place_id, 2);
  m.add(placeScan(3, {{1, 0.95, 1.0}}, policy(2), m.lookup()));
  EXPECT_EQ(m.places[3].place_id, 1);
  EXPECT_TRUE(m.places[3].kept);  // the place's second version
  m.add(placeScan(4, {{3, 0.97, 2.0}, {1, 0.95, 0.1}}, policy(2), m.lookup()));
  EXPECT_EQ(m.places[4].place_id, 1);  // through scan 3, the surer loop
  EXPECT_FALSE(m.places[4].kept);      // the place holds its 2 versions
  // The policy off: every scan is kept.
  EXPECT_TRUE(placeScan(5, {{1, 0.95, 1.0}}, policy(0), m.lookup()).back().kept);
}

TEST(PlaceRule, ACandidateWithoutAPlaceFoundsItAndTiesBreakByDistanceThenId) {
  FakeMap m;
  const auto r = placeScan(9, {{7, 0.95, 1.0}, {5, 0.95, 1.0}, {6, 0.95, 2.0}}, policy(1), m.lookup());
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].scan_id, 5);  // equal probability and distance: the lower id
  EXPECT_EQ(r[0].place_id, 5);
  EXPECT_TRUE(r[0].kept);
  EXPECT_EQ(r[1].place_id, 5);
  EXPECT_FALSE(r[1].kept);  // the founder is the place's one version
}

// ---- Which scans a place keeps, on its own.

PlaceRecord rec(std::int64_t scan, std::int64_t place, bool kept, std::int64_t session, double added_at) {
  PlaceRecord r{scan, place, kept};
  r.session_id = session;
  r.added_at = added_at;
  return r;
}

LoopRecord chose(std::int64_t query, std::int64_t candidate) {
  LoopRecord l;
  l.query_scan = query;
  l.candidate_scan = candidate;
  return l;
}

// Place 1 holds versions 1 (session 1) and 2 (session 2); the latest visits (sessions 3 and 4, from t = 20) left
// surplus scans 3 and 4 there. Scan 5 (session 4, place 2) chose scan 3 later than scan 4 was stored.
std::vector<PlaceRecord> visited() {
  return {rec(1, 1, true, 1, 0), rec(2, 1, true, 2, 10), rec(3, 1, false, 3, 20), rec(4, 1, false, 4, 21),
          rec(5, 5, true, 4, 22)};
}

TEST(Versions, AVersionNoVisitChoseGivesItsSlotToTheVisitThatServedLast) {
  auto places = visited();
  const auto c = rebalanceVersions(places, {chose(3, 1), chose(5, 3)}, policy(2), {});
  EXPECT_EQ(c.promoted, 1);
  EXPECT_EQ(c.demoted, 1);
  ASSERT_EQ(c.changed.size(), 2u);
  EXPECT_EQ(c.changed[0].scan_id, 2);  // scan 3 chose version 1; nothing chose version 2 since it was stored
  EXPECT_FALSE(c.changed[0].kept);
  EXPECT_EQ(c.changed[1].scan_id, 3);  // chosen at t = 22: served later than scan 4 (stored at 21)
  EXPECT_TRUE(c.changed[1].kept);
  EXPECT_TRUE(places[0].kept && !places[1].kept && places[2].kept && !places[3].kept);
  // Without scan 5's choice the two visits served last when stored: the newer takes the slot.
  auto again = visited();
  const auto newer = rebalanceVersions(again, {chose(3, 1)}, policy(2), {});
  ASSERT_EQ(newer.changed.size(), 2u);
  EXPECT_EQ(newer.changed[1].scan_id, 4);
  // The same inputs, the same changes.
  auto twice = visited();
  const auto same = rebalanceVersions(twice, {chose(3, 1), chose(5, 3)}, policy(2), {});
  ASSERT_EQ(same.changed.size(), c.changed.size());
  for (std::size_t i = 0; i < same.changed.size(); ++i) EXPECT_EQ(same.changed[i].scan_id, c.changed[i].scan_id);
}

// A scan serves at the time the scan that chose it was stored: version 2 chose version 1 when it was stored (t = 10),
// and scan 5's later choice of version 2 (t = 22) is not passed on to version 1 (the loops in an order that would
// pass it on if serving were read from the chooser's own last service).
TEST(Versions, ServingIsDatedByTheChoosersStorageAndNotPassedOn) {
  auto places = visited();
  const auto c = rebalanceVersions(places, {chose(5, 2), chose(2, 1)}, policy(2), {});
  ASSERT_EQ(c.changed.size(), 2u);
  EXPECT_EQ(c.changed[0].scan_id, 1);  // last served at t = 10, before the visits began (t = 20)
  EXPECT_FALSE(c.changed[0].kept);
  EXPECT_EQ(c.changed[1].scan_id, 4);  // neither visit was chosen: the newer takes the slot
  EXPECT_TRUE(c.changed[1].kept);
}

TEST(Versions, VersionsTheVisitsChoseStayAndOpenSessionsTakeNoPart) {
  auto places = visited();
  EXPECT_TRUE(rebalanceVersions(places, {chose(3, 1), chose(4, 2)}, policy(2), {}).changed.empty());
  // Sessions 3 and 4 still driven: no visit has ended, nothing is replaced.
  auto open = visited();
  EXPECT_TRUE(rebalanceVersions(open, {}, policy(2), {3, 4}).changed.empty());
  // Only session 4 ended: its visits began at t = 21, after versions 1 and 2 last served; both are unused, and
  // its one surplus scan in place 1 (scan 4) takes the slot of the one that served least (version 1, t = 0).
  auto one = visited();
  const auto c = rebalanceVersions(one, {}, policy(2), {3});
  ASSERT_EQ(c.changed.size(), 2u);
  EXPECT_EQ(c.changed[0].scan_id, 1);
  EXPECT_EQ(c.changed[1].scan_id, 4);
  // The policy's number first: three versions of one session for two slots keep the oldest two (and no
  // replacement: the visit, session 1, began with version 1).
  std::vector<PlaceRecord> over{rec(1, 1, true, 1, 0), rec(2, 1, true, 1, 1), rec(3, 1, true, 1, 5)};
  const auto d = rebalanceVersions(over, {}, policy(2), {});
  EXPECT_EQ(d.demoted, 1);
  EXPECT_EQ(d.promoted, 0);
  EXPECT_FALSE(over[2].kept);
}

// A version chosen within a retention before the latest visits began is in use: a robot that drove by in the
// morning and chose it counts when the afternoon's visit ends, though that visit chose another version.
TEST(Versions, AVersionChosenWithinARetentionBeforeTheVisitsIsInUse) {
  auto in_use = policy(2);
  in_use.session_retention_h = 15.0 / 3600;  // the visits began at t = 20: anything that served since t = 5
  auto places = visited();
  EXPECT_TRUE(rebalanceVersions(places, {chose(3, 1)}, in_use, {}).changed.empty());  // version 2: stored at 10
  in_use.session_retention_h = 5.0 / 3600;  // since t = 15: version 2 is unused
  EXPECT_EQ(rebalanceVersions(places, {chose(3, 1)}, in_use, {}).changed.size(), 2u);
}

// The reviewer's case: the setting lowered to 2 over three versions of three sessions. Step 1 keeps the oldest two;
// the demoted scan is not a visit that could then replace one of them (no scan recorded twice).
TEST(Versions, ASettingLoweredKeepsTheOldestAndItsDemotionsReplaceNothing) {
  std::vector<PlaceRecord> places{rec(1, 1, true, 1, 0), rec(2, 1, true, 2, 10), rec(3, 1, true, 3, 20)};
  const auto c = rebalanceVersions(places, {}, policy(2), {});
  EXPECT_EQ(c.demoted, 1);
  EXPECT_EQ(c.promoted, 0);
  ASSERT_EQ(c.changed.size(), 1u);
  EXPECT_EQ(c.changed[0].scan_id, 3);
  EXPECT_TRUE(places[0].kept && places[1].kept && !places[2].kept);
}

// One visit (session 3) left two scans in a place whose two versions no visit chose: it takes one slot, not both,
// so that the place keeps scans of two drives. Ties: versions of equal service go lower id first, visits of equal
// service newer first. A version of a session still being driven (9) is never replaced.
TEST(Versions, AVisitTakesOneSlotOfAPlaceAndTiesAreBrokenByAge) {
  std::vector<PlaceRecord> places{rec(1, 1, true, 1, 5),   rec(2, 1, true, 2, 5), rec(3, 1, false, 3, 20),
                                  rec(4, 1, false, 3, 20), rec(5, 7, true, 9, 0), rec(6, 7, false, 4, 30),
                                  rec(7, 7, true, 9, 1)};
  const auto c = rebalanceVersions(places, {}, policy(2), {9});
  ASSERT_EQ(c.changed.size(), 2u);
  EXPECT_EQ(c.changed[0].scan_id, 1);  // served at 5 like version 2: the lower id goes
  EXPECT_FALSE(c.changed[0].kept);
  EXPECT_EQ(c.changed[1].scan_id, 4);  // stored at 20 like scan 3: the newer takes the slot
  EXPECT_TRUE(c.changed[1].kept);
  EXPECT_TRUE(places[1].kept && !places[2].kept);  // version 2 stays: session 3 already took a slot
  EXPECT_TRUE(places[4].kept && places[6].kept);   // place 7's versions, of the open session 9, stay
}

// ---- Compaction on a store.

Mat4d at(double x, double y) {
  Mat4d T = Mat4d::Identity();
  T(0, 3) = x;
  T(1, 3) = y;
  return T;
}

// A verified loop from `query` to `candidate` with pose T, probability p and information 1e4 in every direction.
LoopRecord verified(std::int64_t query, std::int64_t candidate, const Mat4d& T, double p) {
  LoopRecord l{0, query, candidate, T, 0.8, 0.9, 0.05, 40};
  l.probability = p;
  l.information = Mat6d::Identity() * 1e4;
  return l;
}

// The (query, candidate) pairs of the map's loops.
std::set<std::pair<std::int64_t, std::int64_t>> loopPairs(MapStore& store) {
  std::set<std::pair<std::int64_t, std::int64_t>> pairs;
  for (const auto& l : store.loops("m")) pairs.insert({l.query_scan, l.candidate_scan});
  return pairs;
}

// Robot "a" drives x = 0..9 m; robot "b" drives the same street 0.2 m to the side, with its odometry in a frame
// of its own (offset 100 m). b's scans 2..7 have verified loops to a's scans at the same x; b_0, b_1, b_8, b_9 none.
struct Street {
  std::vector<std::int64_t> a, b;
  static Mat4d truthA(int k) { return at(k, 0); }
  static Mat4d truthB(int k) { return at(k, 0.2); }
};

Street build(MapStore& store) {
  store.createMap("m", DescriptorLayout{}.scanDim());
  Street s;
  for (const char* robot : {"a", "b"})
    for (int k = 0; k < 10; ++k) {
      const auto fp = randomFingerprint(static_cast<std::uint64_t>(k + (robot[0] == 'b' ? 50 : 0)));
      const Mat4d odom = robot[0] == 'a' ? at(k, 0) : at(100 + k, 0);
      const auto id = store.addScan(
          {.map = "m", .robot = robot, .session = "day", .seq = k, .odometry_pose = odom, .fingerprint = &fp});
      (robot[0] == 'a' ? s.a : s.b).push_back(id);
    }
  for (int k = 2; k < 8; ++k) {
    store.addLoop("m", verified(s.b[k], s.a[k], Street::truthB(k).inverse() * Street::truthA(k), 0.95));
  }
  return s;
}

constexpr double kFuture = 4e9;  // seconds: long after every scan was stored

class Compaction : public storage::testing::OnBothBackends {};

TEST_P(Compaction, RetiresAnEndedSessionsSurplusAndMovesItsLoopsOntoScansThatStay) {
  auto store = db().open();
  const auto s = build(*store);
  const auto before = store->stats("m");
  const auto r = compact(*store, "m", policy(1), OdometryNoise{}, kFuture);
  EXPECT_EQ(r.placed, 20);  // a map built before the policy: every scan placed from its loops
  EXPECT_EQ(r.retired, 6);  // b_2..b_7 relocalized into places that hold their one version
  EXPECT_EQ(r.retired_bytes, before.fingerprint_bytes * 6 / 20);
  EXPECT_EQ(r.loops_moved, 6);
  EXPECT_EQ(r.loops_dropped, 0);
  EXPECT_EQ(r.places, 14);
  EXPECT_EQ(r.versions, 14);
  for (int k = 2; k < 8; ++k) EXPECT_FALSE(store->scanInfo(s.b[k])) << k;
  const auto st = store->stats("m");
  EXPECT_EQ(st.scans, 14);
  EXPECT_EQ(st.index_entries, 14);
  EXPECT_EQ(st.places, 14);
  EXPECT_EQ(st.versions, 14);
  EXPECT_EQ(st.retired_scans, 6);
  EXPECT_EQ(st.retired_bytes, r.retired_bytes);
  // Each loop now ties the nearest kept scan of b (b_1 or b_8) to a_k, with the true relative pose, and less
  // information than the loop it replaces (the odometry between them added).
  const auto loops = store->loops("m");
  ASSERT_EQ(loops.size(), 6u);
  std::set<std::int64_t> stays(s.a.begin(), s.a.end());
  stays.insert({s.b[0], s.b[1], s.b[8], s.b[9]});
  for (const auto& l : loops) {
    ASSERT_TRUE(stays.count(l.query_scan) && stays.count(l.candidate_scan));
    const int k = static_cast<int>(std::find(s.a.begin(), s.a.end(), l.candidate_scan) - s.a.begin());
    ASSERT_LT(k, 10);
    const int anchor = k <= 4 ? 1 : 8;
    EXPECT_EQ(l.query_scan, s.b[anchor]) << k;
    const Mat4d truth = Street::truthB(anchor).inverse() * Street::truthA(k);
    EXPECT_LT((l.T - truth).norm(), 1e-9) << k;
    ASSERT_TRUE(l.information && l.probability);
    EXPECT_LT((*l.information)(0, 0), 1e4);
    EXPECT_GT((*l.information)(0, 0), 0);
    EXPECT_EQ(*l.probability, 0.95);
  }
  // A second compaction finds nothing more to do.
  const auto again = compact(*store, "m", policy(1), OdometryNoise{}, kFuture);
  EXPECT_EQ(again.placed + again.retired + again.loops_moved, 0);
  // The map reopens as it was left (indexes rebuilt or loaded).
  store.reset();
  store = db().open();
  EXPECT_EQ(store->stats("m").index_entries, 14);
  EXPECT_EQ(store->places("m").size(), 14u);
}

// A loop whose candidate end moves onto a scan turned 90 degrees and 2 m away: its information turns with it (the
// registration's weak direction, the candidate's x, becomes the new candidate's y), so that every error costs
// what it cost before the move (no odometry noise here).
TEST_P(Compaction, AMovedCandidateEndTurnsTheLoopsInformationWithIt) {
  auto store = db().open();
  store->createMap("m", DescriptorLayout{}.scanDim());
  const auto fp = randomFingerprint(7);
  Mat4d turned = at(2, 0);
  turned.block<3, 3>(0, 0) = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const auto a0 = store->addScan(
      {.map = "m", .robot = "a", .session = "d", .seq = 0, .odometry_pose = at(0, 5), .fingerprint = &fp});
  const auto b0 = store->addScan(
      {.map = "m", .robot = "b", .session = "d", .seq = 0, .odometry_pose = at(0, 0), .fingerprint = &fp});
  const auto b1 =
      store->addScan({.map = "m", .robot = "b", .session = "d", .seq = 1, .odometry_pose = turned, .fingerprint = &fp});
  store->setPlaces("m", {{a0, a0, true}, {b0, b0, true}, {b1, b0, false}});  // b1: surplus in the place of b0
  Mat6d info = Mat6d::Identity() * 1e4;
  info(0, 0) = 1.0;  // weak along the candidate's x
  LoopRecord l{0, a0, b1, at(1, -4), 0.8, 0.9, 0.05, 40};
  l.probability = 0.95;
  l.information = info;
  store->addLoop("m", l);
  const auto r = compact(*store, "m", policy(1), OdometryNoise{0, 0, 0, 0}, kFuture);
  ASSERT_EQ(r.retired, 1);
  ASSERT_EQ(r.loops_moved, 1);
  const auto moved = store->loops("m").at(0);
  EXPECT_EQ(moved.query_scan, a0);
  EXPECT_EQ(moved.candidate_scan, b0);
  EXPECT_LT((moved.T - l.T * turned.inverse()).norm(), 1e-9);
  const Mat6d& I2 = *moved.information;
  EXPECT_NEAR(I2(1, 1), 1.0, 1e-6);  // the weak direction is now along b0's y
  EXPECT_GT(I2(0, 0), 1e3);
  // A small error xi of the old loop (in b1's frame) is the error Ad(turned) xi of the moved one: same cost.
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0, 1e-3);
  for (int k = 0; k < 20; ++k) {
    Eigen::Matrix<double, 6, 1> xi;
    for (int i = 0; i < 6; ++i) xi[i] = n(rng);
    Mat4d d = Mat4d::Identity();  // Exp(xi) to first order
    d.block<3, 3>(0, 0) = Eigen::AngleAxisd(xi.tail<3>().norm(), xi.tail<3>().normalized()).toRotationMatrix();
    d.block<3, 1>(0, 3) = xi.head<3>();
    const Mat4d err = moved.T.inverse() * (l.T * d * turned.inverse());  // the moved loop's error
    Eigen::Matrix<double, 6, 1> xi2;
    xi2.head<3>() = err.block<3, 1>(0, 3);
    const Eigen::AngleAxisd aa(Eigen::Matrix3d(err.block<3, 3>(0, 0)));
    xi2.tail<3>() = aa.angle() * aa.axis();
    const double before = xi.dot(info * xi), after = xi2.dot(I2 * xi2);
    EXPECT_NEAR(after, before, 1e-2 * before) << k;  // equal to first order (xi ~ 1e-3)
  }
}

// Under a bound of 2, b_1 keeps the loops of b_2 and b_3 (moved 1 and 2 m), not b_4's (3 m); b_8 those of b_7 and
// b_6. The bound counts the loops a scan already has (its own, or moved by earlier compactions): with a loop of
// its own to a_1 (too unsure to tie b_1 to a_1's place), b_1 takes only b_2's.
TEST_P(Compaction, EachScanThatStaysTakesMovedLoopsNearestFirstUpToItsBound) {
  for (const bool own_loop : {false, true}) {
    SCOPED_TRACE(own_loop ? "b_1 has a loop of its own" : "b_1 has no loop");
    auto store = db().open();
    const auto s = build(*store);
    if (own_loop) store->addLoop("m", verified(s.b[1], s.a[1], Street::truthB(1).inverse() * Street::truthA(1), 0.5));
    auto two = policy(1);
    two.max_moved_loops_per_scan = 2;
    const auto r = compact(*store, "m", two, OdometryNoise{}, kFuture);
    EXPECT_EQ(r.retired, 6);
    EXPECT_EQ(r.loops_moved, own_loop ? 3 : 4);
    EXPECT_EQ(r.loops_dropped, own_loop ? 3 : 2);
    std::set<std::pair<std::int64_t, std::int64_t>> expected = {{s.b[1], s.a[2]}, {s.b[8], s.a[6]}, {s.b[8], s.a[7]}};
    expected.insert(own_loop ? std::pair{s.b[1], s.a[1]} : std::pair{s.b[1], s.a[3]});
    EXPECT_EQ(loopPairs(*store), expected);
    store->deleteMap("m");
  }
}

TEST_P(Compaction, SessionsWithinTheirRetentionAndMapsWithThePolicyOffKeepEverything) {
  auto store = db().open();
  build(*store);
  auto keep = policy(1);
  keep.session_retention_h = 1;  // both sessions' last scans were stored a moment ago, within the hour
  const auto now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  const auto open = compact(*store, "m", keep, OdometryNoise{}, now + 60);
  EXPECT_EQ(open.retired, 0);
  EXPECT_EQ(open.open_sessions, 2);
  EXPECT_EQ(open.places, 14);
  EXPECT_EQ(open.versions, 14);  // b_2..b_7 are surplus, waiting for their session to end
  const auto off = compact(*store, "m", policy(0), OdometryNoise{}, kFuture);
  EXPECT_EQ(off.retired, 0);
  EXPECT_EQ(store->stats("m").scans, 20);
  EXPECT_EQ(store->loops("m").size(), 6u);
  // Deleting a session takes its places with it.
  store->deleteSession("m", "b", "day");
  EXPECT_EQ(store->places("m").size(), 10u);
  EXPECT_EQ(store->stats("m").places, 10);
}

TEST_P(Compaction, PlacesLeftWithoutTheirVersionsTakeSurplusScansInstead) {
  auto store = db().open();
  const auto s = build(*store);
  auto keep = policy(1);
  keep.session_retention_h = 1;  // first only places: both sessions are within their retention
  const auto now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  EXPECT_EQ(compact(*store, "m", keep, OdometryNoise{}, now + 60).versions, 14);
  // Robot a's run is deleted: its places would lose the street if b's surplus retired.
  store->deleteSession("m", "a", "day");
  const auto r = compact(*store, "m", policy(1), OdometryNoise{}, kFuture);
  EXPECT_EQ(r.promoted, 6);
  EXPECT_EQ(r.retired, 0);
  EXPECT_EQ(r.versions, 10);
  for (int k = 2; k < 8; ++k) {
    const auto p = store->placeOf(s.b[k]);
    ASSERT_TRUE(p);
    EXPECT_TRUE(p->kept);
  }
  EXPECT_EQ(store->stats("m").scans, 10);
}

TEST_P(Compaction, PlacesOverTheirVersionsKeepTheOldestWhenThePolicyComesOn) {
  auto store = db().open();
  const auto s = build(*store);
  const auto off = compact(*store, "m", policy(0), OdometryNoise{}, kFuture);  // places only, every scan kept
  EXPECT_EQ(off.placed, 20);
  EXPECT_EQ(off.versions, 20);
  EXPECT_EQ(off.retired, 0);
  const auto on = compact(*store, "m", policy(1), OdometryNoise{}, kFuture);
  EXPECT_EQ(on.demoted, 6);  // b_2..b_7, newer than a's versions of their places
  EXPECT_EQ(on.promoted, 0);
  EXPECT_EQ(on.retired, 6);
  EXPECT_EQ(on.versions, 14);
  for (int k = 0; k < 10; ++k) EXPECT_TRUE(store->scanInfo(s.a[k])) << k;
}

// Two versions per place: a's and b's scans of x = 2..7 share places. A later robot c drives there, and its loops
// choose b's scans: a's versions of those places, which no visit chose, give their slots to c's scans and retire.
TEST_P(Compaction, AVersionNoLaterVisitChoseIsReplacedByTheVisitsScan) {
  auto store = db().open();
  const auto s = build(*store);
  const auto first = compact(*store, "m", policy(2), OdometryNoise{}, kFuture);
  EXPECT_EQ(first.versions, 20);
  EXPECT_EQ(first.retired, 0);
  std::vector<std::int64_t> c;
  for (int k = 0; k < 10; ++k) {
    const auto fp = randomFingerprint(static_cast<std::uint64_t>(k + 100));
    c.push_back(store->addScan(
        {.map = "m", .robot = "c", .session = "day", .seq = k, .odometry_pose = at(k, -0.1), .fingerprint = &fp}));
  }
  for (int k = 2; k < 8; ++k) {
    store->addLoop("m", verified(c[k], s.b[k], at(k, -0.1).inverse() * Street::truthB(k), 0.97));
  }
  const auto r = compact(*store, "m", policy(2), OdometryNoise{}, kFuture);
  EXPECT_EQ(r.placed, 10);
  EXPECT_EQ(r.demoted, 6);   // a_2..a_7
  EXPECT_EQ(r.promoted, 6);  // c_2..c_7
  EXPECT_EQ(r.retired, 6);
  EXPECT_EQ(r.versions, 24);
  for (int k = 2; k < 8; ++k) {
    EXPECT_FALSE(store->scanInfo(s.a[k])) << k;
    const auto p = store->placeOf(c[k]);
    ASSERT_TRUE(p) << k;
    EXPECT_TRUE(p->kept);
    EXPECT_EQ(p->place_id, store->placeOf(s.b[k])->place_id);
  }
  // b's loops to the retired a_k now end at a_1 or a_8, each of which takes at most 4.
  for (const auto& l : store->loops("m"))
    EXPECT_TRUE(store->scanInfo(l.query_scan) && store->scanInfo(l.candidate_scan));
  const auto again = compact(*store, "m", policy(2), OdometryNoise{}, kFuture);
  EXPECT_EQ(again.retired + again.promoted + again.demoted, 0);
}

TEST_P(Compaction, ScansOfSessionsStillBeingDrivenAreLeftToTheirIngest) {
  auto store = db().open();
  const auto s = build(*store);
  store->setPlaces("m", {{s.b[0], s.b[0], true}});  // b's ingest placed its first scan a moment ago
  auto keep = policy(1);
  keep.session_retention_h = 1;
  const auto now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  const auto open = compact(*store, "m", keep, OdometryNoise{}, now + 60);
  EXPECT_EQ(open.placed, 10);  // a's scans (a session with no place yet is not known to be driven); none of b's
  EXPECT_EQ(open.open_sessions, 2);
  EXPECT_FALSE(store->placeOf(s.b[5]));
  const auto later = compact(*store, "m", policy(1), OdometryNoise{}, kFuture);
  EXPECT_EQ(later.placed, 9);
  EXPECT_EQ(later.retired, 6);
}

TEST_P(Compaction, SetPlacesRefusesAScanOfAnotherMapAndRecordsNothing) {
  auto store = db().open();
  const auto s = build(*store);
  store->createMap("other", DescriptorLayout{}.scanDim());
  EXPECT_EQ(storage::testing::errorCode([&] {
              store->setPlaces("other", {{s.a[0], s.a[0], true}});
            }),
            storage::StorageError::Code::kNotFound);
  EXPECT_EQ(storage::testing::errorCode([&] {
              store->setPlaces("m", {{s.a[0], s.a[0], true}, {999999, 999999, true}});
            }),
            storage::StorageError::Code::kNotFound);
  EXPECT_TRUE(store->places("m").empty());
  EXPECT_FALSE(store->placeOf(s.a[0]));
}

INSTANTIATE_TEST_SUITE_P(MapStore, Compaction, ::testing::Values("sqlite", "postgresql"),
                         [](const auto& info) { return info.param; });

}  // namespace
}  // namespace sglc::closing
