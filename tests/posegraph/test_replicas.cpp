// Two servers on one PostgreSQL map: one solves the pose graph, the other follows its versions, and takes the
// map over when the first stops.
#include <gtest/gtest.h>

#include <atomic>
#include <mutex>
#include <thread>

#include "../storage/backend.hpp"
#include "drive.hpp"

namespace sglc::posegraph {
namespace {

using namespace std::chrono_literals;
using testing::drive;
using testing::driveOptions;

GraphOptimiserOptions fastPolls() {
  auto o = driveOptions();
  o.replica_poll_s = 0.1;
  o.debounce = 20ms;
  return o;
}

// Robot "bad": 20 scans, each tied by a wrong loop to a first-lap scan.
void addBadRobot(storage::MapStore& s, const testing::Drive& d) {
  for (int i = 0; i < 20; ++i) {
    const auto fp = storage::testing::randomFingerprint(1000 + static_cast<std::uint64_t>(i));
    const auto id = s.addScan({.map = "m",
                               .robot = "bad",
                               .session = "b",
                               .seq = i,
                               .odometry_pose = testing::pose(0, 2.0 * i, 0),
                               .fingerprint = &fp});
    s.addLoop("m", {0, id, d.ids[10 + static_cast<std::size_t>(i)], testing::pose(0.5, 7, -3), 0.8, 0.9, 0.02, 20});
  }
}

// The first event of `g` for map "m" after version `after` that comes from a solve of its own (not a followed
// version, whose nodes are 0) and satisfies `done`; nullopt after two minutes.
std::optional<GraphEvent> solvedUntil(GraphOptimiser& g, std::int64_t after,
                                      const std::function<bool(const GraphEvent&)>& done) {
  for (int i = 0; i < 240; ++i) {
    const auto e = g.waitForVersion("m", after, 120s);
    if (!e || e->failed) return e;
    if (e->nodes > 0 && done(*e)) return e;
    after = e->graph_version;
  }
  return std::nullopt;
}

// Two stores on one fresh PostgreSQL database, as two servers have.
class Replicas : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!db.unavailable().empty()) GTEST_SKIP() << db.unavailable();
    store_a = db.open();
    store_b = db.open();
  }
  storage::testing::Backend db{"postgresql"};
  std::unique_ptr<storage::MapStore> store_a, store_b;
};

TEST_F(Replicas, OneServerSolvesAMapTheOtherFollowsAndTakesOverWhenItStops) {
  const auto d = drive(*store_a);
  const auto options = fastPolls();
  auto a = std::make_unique<GraphOptimiser>(*store_a, options);
  const auto first = a->waitForVersion("m", 0, 120s);  // a starts first: it holds the map
  ASSERT_TRUE(first && !first->failed);
  EXPECT_EQ(first->nodes, 240);
  const auto map_id = store_a->findMap("m")->id;
  EXPECT_EQ(store_b->claimGraph(map_id), storage::MapStore::GraphClaim::kElsewhere);

  GraphOptimiser b(*store_b, options);
  const auto followed = b.waitForVersion("m", 0, 120s);  // b follows a's stored version, solving nothing
  ASSERT_TRUE(followed && !followed->failed);
  EXPECT_EQ(followed->nodes, 0);
  EXPECT_GE(followed->graph_version, first->graph_version);

  // A loop stored through b: a finds it on its next poll and solves it; b follows the new version.
  const auto before = store_b->graphVersion("m");
  store_b->addLoop("m", {0, d.ids[200], d.ids[80], d.gt[200].inverse() * d.gt[80], 0.8, 0.9, 0.02, 20});
  b.loopsAdded("m");
  const auto solved_by_a = a->waitForVersion("m", before, 120s);
  ASSERT_TRUE(solved_by_a && !solved_by_a->failed);
  EXPECT_GT(solved_by_a->nodes, 0);
  ASSERT_TRUE(b.waitForVersion("m", solved_by_a->graph_version - 1, 120s));

  // a stops (its store closes, and its lock with it): b takes the map over and solves it itself.
  const auto version = store_b->graphVersion("m");
  a.reset();
  store_a.reset();
  const auto taken = solvedUntil(b, version, [](const GraphEvent&) { return true; });  // b's own solve
  ASSERT_TRUE(taken && !taken->failed);
  EXPECT_EQ(taken->nodes, 240);
  EXPECT_NE(store_b->claimGraph(map_id), storage::MapStore::GraphClaim::kElsewhere);
  EXPECT_LT(testing::ate(testing::optimised(*store_b), d.gt), 0.2);
}

// Sessions or robots deleted through a server that does not hold the map: the holder rebuilds its graph
// without them (it kept solving the deleted scans and their loops before).
TEST_F(Replicas, ScansDeletedThroughAnotherServerLeaveTheHoldersGraph) {
  const auto d = drive(*store_a);
  addBadRobot(*store_a, d);
  GraphOptimiser a(*store_a, fastPolls());
  const auto first = a.waitForVersion("m", 0, 120s);
  ASSERT_TRUE(first && !first->failed);
  EXPECT_EQ(first->nodes, 260);
  GraphOptimiser b(*store_b, fastPolls());
  ASSERT_TRUE(b.waitForVersion("m", 0, 120s));
  EXPECT_EQ(store_b->deleteRobot("m", "bad"), 20);  // the call reached b, as a balancer may route it
  b.scansRemoved("m");
  const auto e = solvedUntil(a, first->graph_version, [](const GraphEvent& e) { return e.nodes == 240; });
  ASSERT_TRUE(e && !e->failed) << "the holder never dropped the deleted scans";
  EXPECT_EQ(static_cast<std::size_t>(e->loops), store_a->loops("m", 0, 0).size());
  EXPECT_LT(testing::ate(testing::optimised(*store_a), d.gt), 0.2);
}

// A map deleted through one server is announced on the others (their WatchMap streams end), and a lock that was
// lost and taken again starts from the stored rows, not from the graph kept from before.
TEST_F(Replicas, DeletionsAndLostLocksAreSeenByEveryServer) {
  const auto d = drive(*store_a);
  addBadRobot(*store_a, d);
  auto a = std::make_unique<GraphOptimiser>(*store_a, fastPolls());
  ASSERT_TRUE(a->waitForVersion("m", 0, 120s));
  // a's lock connection ends (a network blip); b takes the map over, deletes robot "bad" and solves without it.
  storage::pg::Conn(db.options().path).exec(storage::testing::kEndThisDatabasesLockHolders);
  auto b = std::make_unique<GraphOptimiser>(*store_b, fastPolls());
  const auto taken = solvedUntil(*b, 0, [](const GraphEvent&) { return true; });
  ASSERT_TRUE(taken && !taken->failed);
  store_b->deleteRobot("m", "bad");
  b->scansRemoved("m");
  ASSERT_TRUE(solvedUntil(*b, taken->graph_version, [](const GraphEvent& e) { return e.nodes == 240; }));
  b.reset();
  store_b.reset();
  // a takes the lock again: its graph is rebuilt from the stored rows (240 nodes, not its old 260).
  const auto before = store_a->graphVersion("m");
  store_a->addLoop("m", {0, d.ids[200], d.ids[80], d.gt[200].inverse() * d.gt[80], 0.8, 0.9, 0.02, 20});
  a->loopsAdded("m");
  const auto again = solvedUntil(*a, before, [](const GraphEvent&) { return true; });
  ASSERT_TRUE(again && !again->failed);
  EXPECT_EQ(again->nodes, 240);

  // The map deleted through a third server: a announces it to its listeners.
  auto store_c = db.open();
  std::mutex mutex;
  bool heard = false;
  const auto id = a->subscribe([&](const std::string& map, const GraphEvent& e) {
    std::lock_guard lock(mutex);
    heard |= map == "m" && e.deleted;
  });
  store_c->deleteMap("m");
  for (int i = 0; i < 12000; ++i) {
    {
      std::lock_guard lock(mutex);
      if (heard) break;
    }
    std::this_thread::sleep_for(10ms);
  }
  a->unsubscribe(id);
  std::lock_guard lock(mutex);
  EXPECT_TRUE(heard) << "listeners on a never heard that the map was deleted";
}

// A held map with nothing new is not solved again on every poll (a map whose scans have no odometry, so its graph
// has no nodes, was solved "fresh" and given a new version each time).
TEST_F(Replicas, AnIdleMapIsNotSolvedAgainOnEveryPoll) {
  storage::testing::Backend db("postgresql");
  if (!db.unavailable().empty()) GTEST_SKIP() << db.unavailable();
  auto& store = store_a;
  store->createMap("m", DescriptorLayout{}.scanDim());
  std::vector<std::int64_t> ids;
  for (int i = 0; i < 10; ++i) {
    const auto fp = storage::testing::randomFingerprint(100 + static_cast<std::uint64_t>(i));
    ids.push_back(store->addScan({.map = "m", .robot = "r", .session = "s", .seq = i, .fingerprint = &fp}));
  }
  store->addLoop("m", {0, ids[9], ids[0], testing::pose(0, 1, 0), 0.8, 0.9, 0.02, 20});
  std::atomic<int> events{0};
  GraphOptimiser a(*store, fastPolls());
  const auto id = a.subscribe([&](const std::string&, const GraphEvent&) { ++events; });
  std::this_thread::sleep_for(3s);  // some 30 polls; a slower machine polls less, which cannot fail the test
  a.unsubscribe(id);
  EXPECT_LE(events.load(), 2) << "the idle map was solved again on polls";
  EXPECT_LE(store->graphVersion("m"), 2);
}

}  // namespace
}  // namespace sglc::posegraph
