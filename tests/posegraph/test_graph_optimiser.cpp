// GraphOptimiser on a real map database: a drifting two-lap drive with exact loops, with and without a planted
// false loop, and a restart that continues from the stored poses.
#include <gtest/gtest.h>

#include <atomic>

#include <filesystem>
#include <mutex>
#include <random>
#include <string>
#include <thread>

#include "../storage/storage_test_util.hpp"
#include "drive.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"

namespace sglc::posegraph {
namespace {

using storage::testing::options;
using storage::testing::randomFingerprint;
using storage::testing::TempDir;
using testing::ate;
using testing::drive;
using testing::driveOptions;
using testing::optimised;
using testing::pose;

TEST(GraphOptimiser, LoopsRemoveDriftAndAFalseLoopIsDiscounted) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  GraphOptimiser graph(*store, driveOptions());
  const auto e = graph.optimiseNow("m");
  EXPECT_EQ(e.nodes, 240);
  EXPECT_GE(e.graph_version, 1);
  EXPECT_EQ(e.rejected_loops, 0);
  const auto est = optimised(*store);
  ASSERT_EQ(est.size(), d.gt.size());
  const double ate_odom = ate(d.odom, d.gt), ate_opt = ate(est, d.gt);
  std::cout << "ATE odometry " << ate_odom << " m, optimised " << ate_opt << " m, " << e.optimise_ms << " ms\n";
  EXPECT_LT(ate_opt, ate_odom / 4);

  // A false loop: scan 200 claimed to be 1 m from scan 20 (they are ~70 m apart).
  store->addLoop("m", {0, d.ids[200], d.ids[20], pose(0.0, 1.0, 0.0), 0.9, 0.9, 0.02, 30});
  const auto e2 = graph.optimiseNow("m");
  EXPECT_GT(e2.graph_version, e.graph_version);
  EXPECT_EQ(e2.loops, 40);
  EXPECT_GE(e2.rejected_loops, 1);
  const double ate_false = ate(optimised(*store), d.gt);
  std::cout << "with a false loop: ATE " << ate_false << " m, rejected " << e2.rejected_loops << "\n";
  EXPECT_LT(ate_false, ate_opt * 1.10 + 0.01);
}

// A loop registered in a corridor knows nothing along it: its information says so, and a 1 m error in that
// direction must neither pull the graph nor count as rejected. The same error with isotropic information is an
// outlier.
TEST(GraphOptimiser, LoopInformationLeavesFreeDirectionsFree) {
  const auto o = driveOptions();
  Mat6d corridor = Mat6d::Zero();  // 2 mm / 0.02 deg in every direction but the loop's own x
  corridor.diagonal() << 0.0, 2.5e5, 2.5e5, 8e6, 8e6, 8e6;
  double ate_reference = 0;
  for (const bool isotropic : {false, true}) {
    SCOPED_TRACE(isotropic ? "isotropic" : "corridor");
    TempDir dir;
    auto store = storage::MapStore::open(options(dir.file("map.db")));
    const auto d = drive(*store);
    GraphOptimiser graph(*store, o);
    const auto e = graph.optimiseNow("m");
    ASSERT_EQ(e.rejected_loops, 0);
    ate_reference = ate(optimised(*store), d.gt);
    // Scans 150 and 30 are the same place; the loop claims 1 m along its x.
    storage::LoopRecord l{0,   d.ids[150], d.ids[30], d.gt[150].inverse() * d.gt[30] * pose(0.0, 1.0, 0.0),
                          0.8, 0.9,        0.02,      20};
    l.information = corridor;
    if (isotropic) l.information->diagonal()[0] = 2.5e5;
    store->addLoop("m", l);
    const auto e2 = graph.optimiseNow("m");
    const double ate_after = ate(optimised(*store), d.gt);
    std::cout << (isotropic ? "isotropic" : "corridor") << ": ATE " << ate_reference << " -> " << ate_after
              << " m, rejected " << e2.rejected_loops << "\n";
    if (isotropic) {
      EXPECT_EQ(e2.rejected_loops, 1);
    } else {
      EXPECT_EQ(e2.rejected_loops, 0);
      EXPECT_LT(std::abs(ate_after - ate_reference), 0.002);
    }
  }
}

TEST(GraphOptimiser, ARestartContinuesFromTheStoredPosesAndWakesWatchers) {
  TempDir dir;
  const auto path = dir.file("map.db");
  std::vector<Mat4d> first;
  {
    auto store = storage::MapStore::open(options(path));
    const auto d = drive(*store);
    GraphOptimiser graph(*store, {});
    graph.optimiseNow("m");
    // A false loop far off the solution, added once the graph is solved: discounted, and it must stay so
    // after the restart (not re-solved as if new, which would move the poses).
    store->addLoop("m", {0, d.ids[200], d.ids[20], pose(0.0, 1.0, 0.0), 0.9, 0.9, 0.02, 30});
    EXPECT_GE(graph.optimiseNow("m").rejected_loops, 1);
    first = optimised(*store);
  }
  auto store = storage::MapStore::open(options(path));
  const auto stored = store->graphVersion("m");
  EXPECT_GE(stored, 1);
  GraphOptimiser graph(*store, {.debounce = std::chrono::milliseconds(10)});  // maps with loops: optimised on start
  const auto event = graph.waitForVersion("m", stored, std::chrono::seconds(60));
  ASSERT_TRUE(event.has_value());
  EXPECT_EQ(event->graph_version, stored + 1);
  const auto again = optimised(*store);
  ASSERT_EQ(again.size(), first.size());
  double moved = 0;
  for (std::size_t i = 0; i < first.size(); ++i)
    moved = std::max(moved, (again[i].block<3, 1>(0, 3) - first[i].block<3, 1>(0, 3)).norm());
  EXPECT_LT(moved, 0.01);  // warm-started from its own solution: stays put
  // Nothing new without new loops.
  EXPECT_FALSE(graph.waitForVersion("m", stored + 1, std::chrono::milliseconds(300)).has_value());
  graph.stop();
  EXPECT_TRUE(graph.stopping());
}

// A solve cut short by its iteration bound says so, and the worker goes on from its poses until the graph
// converges; with no continuations allowed it stays where it stopped until something new arrives.
TEST(GraphOptimiser, AnUnconvergedSolveIsContinued) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  GraphOptimiserOptions o;
  o.debounce = std::chrono::milliseconds(10);
  o.max_iterations = 2;
  o.max_continuations = 0;
  std::int64_t version = 0;
  {
    GraphOptimiser graph(*store, o);  // the start-up solve of the map is the only one
    const auto e = graph.waitForVersion("m", 0, std::chrono::seconds(60));
    ASSERT_TRUE(e.has_value());
    EXPECT_FALSE(e->converged);
    version = e->graph_version;
    EXPECT_FALSE(graph.waitForVersion("m", version, std::chrono::milliseconds(300)).has_value());
  }
  o.max_continuations = 1000;
  GraphOptimiser graph(*store, o);
  std::optional<GraphEvent> e;
  int solves = 0;
  do {
    e = graph.waitForVersion("m", version, std::chrono::seconds(60));
    ASSERT_TRUE(e.has_value()) << "no further solve after version " << version;
    version = e->graph_version;
    ++solves;
  } while (!e->converged && solves < 500);
  EXPECT_TRUE(e->converged) << solves << " solves";
  EXPECT_GT(solves, 1);
  EXPECT_LT(ate(optimised(*store), d.gt), 0.5 * ate(d.odom, d.gt));
}

// Deleting a session takes its scans and loops out of the graph: the map is solved again without them, from
// the poses it had, and a loop recorded twice for the same pair counts once (the second replaces the first).
TEST(GraphOptimiser, DeletedScansAndReplacedLoopsLeaveTheGraph) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  GraphOptimiser graph(*store, {.debounce = std::chrono::milliseconds(10)});
  // The map has loops, so the worker solves it on start; wait for that, so that below only the deletion
  // schedules work.
  const auto start = graph.waitForVersion("m", 0, std::chrono::seconds(60));
  ASSERT_TRUE(start.has_value());
  // Nothing new since: no second solve, the same event and version.
  const auto e = graph.optimiseNow("m");
  EXPECT_EQ(e.graph_version, start->graph_version);
  EXPECT_EQ(store->graphVersion("m"), start->graph_version);
  ASSERT_EQ(e.loops, 39);
  const auto solved = optimised(*store);
  // A second robot whose (false) loops claim the first lap is 3 m off: they pull until it is deleted.
  std::vector<std::int64_t> other;
  for (int i = 0; i < 10; ++i) {
    const auto fp = randomFingerprint(1000 + i);
    storage::NewScan ns{
        .map = "m", .robot = "x", .session = "s", .seq = i, .odometry_pose = pose(0, 2.0 * i, 0), .fingerprint = &fp};
    other.push_back(store->addScan(ns));
  }
  for (int i = 0; i < 10; ++i)
    store->addLoop("m", {0, other[static_cast<std::size_t>(i)], d.ids[static_cast<std::size_t>(10 + i)],
                         pose(0, 3.0, 0), 0.9, 0.9, 0.02, 30});
  // The same pair again: replaces the loop above in the database and must do so in the graph.
  store->addLoop("m", {0, other[0], d.ids[10], pose(0, 3.0, 0), 0.9, 0.9, 0.02, 31});
  const auto e2 = graph.optimiseNow("m");
  EXPECT_EQ(e2.nodes, 250);
  EXPECT_EQ(e2.loops, 49);
  const auto version = store->graphVersion("m");
  EXPECT_EQ(store->deleteRobot("m", "x"), 10);
  graph.scansRemoved("m");
  const auto e3 = graph.waitForVersion("m", version, std::chrono::seconds(60));
  ASSERT_TRUE(e3.has_value());
  EXPECT_EQ(e3->nodes, 240);
  EXPECT_EQ(e3->loops, 39);
  EXPECT_EQ(e3->rejected_loops, 0);
  const auto after = optimised(*store);
  ASSERT_EQ(after.size(), solved.size());
  double moved = 0;
  for (std::size_t i = 0; i < after.size(); ++i)
    moved = std::max(moved, (after[i].block<3, 1>(0, 3) - solved[i].block<3, 1>(0, 3)).norm());
  EXPECT_LT(moved, 0.01);  // back where it was without the deleted robot
  graph.stop();
}

TEST(GraphOptimiser, ADeletedMapIsForgottenAndItsNameStartsAfresh) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  // Made before the map exists, so that it schedules no start-up solve of its own: only optimiseNow solves here
  // (a background solve racing the test's would publish events of its own, all of them legitimate).
  GraphOptimiser graph(*store, {.debounce = std::chrono::hours(1)});
  drive(*store);
  const auto first = graph.optimiseNow("m");
  ASSERT_FALSE(first.failed) << first.error;
  EXPECT_EQ(first.nodes, 240);
  std::atomic<int> events{0}, deleted{0};
  const auto id = graph.subscribe([&](const std::string&, const GraphEvent& e) { ++(e.deleted ? deleted : events); });
  const auto map_id = store->findMap("m")->id;
  EXPECT_EQ(store->deleteMap("m"), 240);
  graph.mapDeleted("m", map_id);
  EXPECT_EQ(deleted.load(), 1);  // listeners (watch streams) hear that the map is gone
  EXPECT_FALSE(graph.latest("m").has_value());
  // A solve of the deleted map (one already queued, or racing the delete) says so and publishes nothing.
  const auto gone = graph.optimiseNow("m");
  EXPECT_TRUE(gone.failed);
  EXPECT_EQ(gone.error, "the map was deleted");
  EXPECT_EQ(events.load(), 0);
  EXPECT_FALSE(graph.latest("m").has_value());
  // The same name again: a graph of the new scans only, not the deleted map's graph with them added.
  drive(*store);
  const auto fresh = graph.optimiseNow("m");
  ASSERT_FALSE(fresh.failed) << fresh.error;
  EXPECT_EQ(fresh.nodes, 240);
  EXPECT_EQ(fresh.loops, first.loops);
  EXPECT_EQ(events.load(), 1);
  EXPECT_EQ(deleted.load(), 1);
  graph.unsubscribe(id);
}

// The worker sleeps until a map's solve is due; a delete meanwhile drops the map's schedule. The worker must not
// read the dropped entry when it wakes (it did: a use after free that AddressSanitizer caught in sglc_eval_cli).
// Each round gives the worker time to be asleep on the map's deadline, so the ASan build sees the read if it returns.
TEST(GraphOptimiser, AMapDeletedWhileItsSolveIsScheduledLeavesTheWorkerSound) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  GraphOptimiser graph(*store, {.debounce = std::chrono::hours(1)});
  for (int i = 0; i < 5; ++i) {
    const std::string map = "gone" + std::to_string(i);
    graph.loopsAdded(map);
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    graph.mapDeleted(map, 0);
    EXPECT_FALSE(graph.latest(map).has_value());
  }
  drive(*store);  // and it still solves
  const auto solved = graph.optimiseNow("m");
  ASSERT_FALSE(solved.failed) << solved.error;
  EXPECT_EQ(solved.nodes, 240);
}

// A delete and a new map of the same name can both happen between two solves, before the optimiser hears of the
// delete (mapDeleted comes after the store's delete): the next solve sees a new map id and starts a new graph.
TEST(GraphOptimiser, AMapCreatedAgainUnderItsNameIsANewGraphEvenBeforeTheDeleteIsAnnounced) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  GraphOptimiser graph(*store, {.debounce = std::chrono::hours(1)});
  drive(*store);
  const auto first = graph.optimiseNow("m");
  ASSERT_FALSE(first.failed) << first.error;
  EXPECT_EQ(store->deleteMap("m"), 240);
  drive(*store);
  const auto again = graph.optimiseNow("m");
  ASSERT_FALSE(again.failed) << again.error;
  EXPECT_EQ(again.nodes, 240);  // not 480: the deleted map's nodes are not kept
  EXPECT_EQ(again.loops, first.loops);
  EXPECT_EQ(optimised(*store).size(), 240u);
}

// A database written before the server checked poses may hold scans whose odometry pose is no rigid motion
// (the all-zero rotation that crashed the server in a loop) and loops with a damaged transform: the optimiser
// leaves them out and solves the rest; it never aborts.
TEST(GraphOptimiser, PosesThatAreNotRigidMotionsAreLeftOut) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  Mat4d zero = Mat4d::Zero();
  zero(3, 3) = 1;
  Mat4d tiny = Mat4d::Identity() * 1e-300;
  tiny(3, 3) = 1;
  Mat4d sheared = Mat4d::Identity();
  sheared(0, 1) = 0.5;
  std::vector<std::int64_t> bad;
  int seq = 0;
  for (const Mat4d& T : {zero, zero, tiny, sheared}) {
    const auto fp = randomFingerprint(500 + seq);
    storage::NewScan ns{
        .map = "m", .robot = "bad", .session = "s", .seq = seq++, .odometry_pose = T, .fingerprint = &fp};
    bad.push_back(store->addScan(ns));
  }
  store->addLoop("m", {0, bad[1], bad[0], zero, 0.9, 0.9, 0.02, 30});
  store->addLoop("m", {0, bad[0], d.ids[3], pose(0, 1, 0), 0.9, 0.9, 0.02, 30});
  store->addLoop("m", {0, d.ids[200], d.ids[7], zero, 0.9, 0.9, 0.02, 30});  // good scans, damaged loop
  GraphOptimiser graph(*store, {.debounce = std::chrono::milliseconds(10)});
  const auto e = graph.optimiseNow("m");
  EXPECT_FALSE(e.failed) << e.error;
  EXPECT_EQ(e.nodes, 240);  // the four bad scans are no nodes
  EXPECT_EQ(e.loops, 39);   // nor are the loops that touch them or carry a damaged transform
  const auto est = optimised(*store);
  ASSERT_EQ(est.size(), 240u);
  for (const auto& T : est) EXPECT_TRUE(T.allFinite());
  EXPECT_LT(ate(est, d.gt), ate(d.odom, d.gt));
  graph.stop();
}

// A solve whose result cannot be written (here: the database reached its size limit) marks the map's graph
// failed, tells its watchers, keeps the last good poses, and the next successful solve clears it.
TEST(GraphOptimiser, AFailedSolveIsReportedAndTheMapKeepsItsPoses) {
  TempDir dir;
  const auto path = dir.file("map.db");
  {
    auto store = storage::MapStore::open(options(path));
    drive(*store);
  }
  auto limited = options(path);
  limited.max_db_mb = static_cast<double>(std::filesystem::file_size(path)) / (1024 * 1024);
  {
    auto store = storage::MapStore::open(limited);
    GraphOptimiser graph(*store, {.debounce = std::chrono::hours(1)});  // only the start-up solve runs itself
    std::vector<GraphEvent> heard;
    std::mutex m;
    const auto id = graph.subscribe([&](const std::string& map, const GraphEvent& e) {
      std::lock_guard lock(m);
      if (map == "m") heard.push_back(e);
    });
    const auto e = graph.optimiseNow("m");
    EXPECT_TRUE(e.failed);
    EXPECT_NE(e.error.find("full"), std::string::npos) << e.error;
    EXPECT_EQ(e.graph_version, 0);
    EXPECT_EQ(store->graphVersion("m"), 0);
    EXPECT_TRUE(store->optimisedPoses("m", "", "", 0, 10).empty());
    ASSERT_TRUE(graph.latest("m").has_value());
    EXPECT_TRUE(graph.latest("m")->failed);
    graph.unsubscribe(id);
    std::lock_guard lock(m);
    ASSERT_FALSE(heard.empty());
    EXPECT_TRUE(heard.back().failed);
    graph.stop();
  }
  auto store = storage::MapStore::open(options(path));
  GraphOptimiser graph(*store, {.debounce = std::chrono::hours(1)});
  const auto e = graph.optimiseNow("m");
  EXPECT_FALSE(e.failed) << e.error;
  EXPECT_GE(e.graph_version, 1);
  graph.stop();
}

}  // namespace
}  // namespace sglc::posegraph
