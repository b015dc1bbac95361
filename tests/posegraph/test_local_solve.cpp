// Bounded cost per loop event: a new loop that agrees with the solved graph frees only the nodes around it
// (the rest keep their stored poses exactly), one far off the graph still solves everything, and the worker
// follows local solves with a global one within its interval, ending where global solves alone end.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "drive.hpp"
#include "map_graph.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"

namespace sglc::posegraph {
namespace {

using storage::testing::options;
using storage::testing::TempDir;
using testing::drive;
using testing::Drive;
using testing::optimised;
using testing::pose;

constexpr int kWindow = 5;

// The drive's odometry model; a window small enough for the 240-node drive to solve locally.
GraphOptimiserOptions localOptions() {
  auto o = testing::driveOptions();
  o.debounce = std::chrono::hours(1);  // only optimiseNow solves, apart from the worker's start-up solve
  o.local_window = kWindow;
  o.global_interval_s = 3600;
  return o;
}

// An exact loop from scan i (second lap) to scan i - 120 (first lap); the drive's loops use every third i from
// 125, so these are new pairs.
void addLoop(storage::MapStore& store, const Drive& d, int i) {
  ASSERT_NE((i - 125) % 3, 0) << "the drive has a loop from scan " << i << " already";
  const auto j = static_cast<std::size_t>(i - 120), k = static_cast<std::size_t>(i);
  ASSERT_GT(store.addLoop("m", {0, d.ids[k], d.ids[j], d.gt[k].inverse() * d.gt[j], 0.8, 0.9, 0.02, 20}), 0);
}

// The drive's graph in memory, solved whole.
MapGraph solvedGraph(const storage::MapStore& store) {
  MapGraph g;
  EXPECT_TRUE(g.absorb("m", store.loops("m"), store.graphNodes("m"), {}));
  g.solve(localOptions(), 0, false);
  return g;
}

// Takes the loops stored since the graph last read them.
void absorbNewLoops(MapGraph& g, const storage::MapStore& store) {
  ASSERT_TRUE(g.absorb("m", store.loops("m", g.lastLoop()), {}, {}));
}

double maxShift(const std::vector<Mat4d>& a, const std::vector<Mat4d>& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, (a[i].block<3, 1>(0, 3) - b[i].block<3, 1>(0, 3)).norm());
  return m;
}

TEST(LocalSolve, AnAgreeingLoopMovesOnlyTheNodesAroundIt) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  GraphOptimiser graph(*store, localOptions());
  const auto d = drive(*store);
  const auto first = graph.optimiseNow("m");
  ASSERT_FALSE(first.failed) << first.error;
  EXPECT_TRUE(first.global);  // a new graph is solved whole
  const auto before = optimised(*store);

  addLoop(*store, d, 201);
  const auto e = graph.optimiseNow("m");
  ASSERT_FALSE(e.failed) << e.error;
  EXPECT_FALSE(e.global);
  // Scans 196..206 and 76..86: the loop's ends and kWindow on either side.
  EXPECT_EQ(e.free_nodes, 2 * (2 * kWindow + 1));
  EXPECT_EQ(e.loops, first.loops + 1);
  EXPECT_GT(e.graph_version, first.graph_version);
  const auto after = optimised(*store);
  ASSERT_EQ(after.size(), before.size());
  int moved = 0;
  for (std::size_t i = 0; i < after.size(); ++i) {
    const bool in_window = (i >= 196 && i <= 206) || (i >= 76 && i <= 86);
    if (!in_window) {
      EXPECT_EQ(after[i], before[i]) << "scan " << i << " is outside the windows";
    }
    moved += after[i] != before[i];
  }
  EXPECT_GT(moved, 0);
  EXPECT_LT(maxShift(after, before), 0.2);
}

TEST(LocalSolve, ALoopFarOffTheGraphIsSolvedGlobally) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  GraphOptimiser graph(*store, localOptions());
  const auto d = drive(*store);
  ASSERT_FALSE(graph.optimiseNow("m").failed);
  // Scan 200 claimed to be 1 m from scan 20: they are ~70 m apart. The graduated global solve discounts it.
  store->addLoop("m", {0, d.ids[200], d.ids[20], pose(0.0, 1.0, 0.0), 0.9, 0.9, 0.02, 30});
  const auto e = graph.optimiseNow("m");
  ASSERT_FALSE(e.failed) << e.error;
  EXPECT_TRUE(e.global);
  EXPECT_EQ(e.free_nodes, 240);
  EXPECT_GE(e.rejected_loops, 1);
}

TEST(LocalSolve, AWindowOfZeroSolvesEveryEventGlobally) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  auto o = localOptions();
  o.local_window = 0;
  GraphOptimiser graph(*store, o);
  const auto d = drive(*store);
  ASSERT_FALSE(graph.optimiseNow("m").failed);
  addLoop(*store, d, 201);
  const auto e = graph.optimiseNow("m");
  EXPECT_TRUE(e.global);
  EXPECT_EQ(e.free_nodes, 240);
}

// Local events and then one global solve end where a global solve per event ends.
TEST(LocalSolve, LocalEventsThenAGlobalSolveMatchGlobalSolvesAlone) {
  TempDir dir;
  auto local_store = storage::MapStore::open(options(dir.file("local.db")));
  auto global_store = storage::MapStore::open(options(dir.file("global.db")));
  auto global_options = localOptions();
  global_options.local_window = 0;
  GraphOptimiser local(*local_store, localOptions()), global(*global_store, global_options);
  const auto dl = drive(*local_store), dg = drive(*global_store);
  ASSERT_FALSE(local.optimiseNow("m").failed);
  ASSERT_FALSE(global.optimiseNow("m").failed);
  int local_events = 0;
  for (const int i : {201, 210, 216, 222, 231}) {
    addLoop(*local_store, dl, i);
    addLoop(*global_store, dg, i);
    local_events += !local.optimiseNow("m").global;
    ASSERT_TRUE(global.optimiseNow("m").global);
  }
  EXPECT_EQ(local_events, 5);
  const auto settled = local.optimiseNow("m", GraphOptimiser::Scope::kGlobal);
  EXPECT_TRUE(settled.global);
  EXPECT_LT(maxShift(optimised(*local_store), optimised(*global_store)), 1e-3);
}

// Every event the optimiser publishes, in order, for a test to wait on (whatever the threads' timing).
class Events {
 public:
  explicit Events(GraphOptimiser& graph) : graph_(graph) {
    id_ = graph.subscribe([this](const std::string&, const GraphEvent& e) {
      std::lock_guard lock(m_);
      events_.push_back(e);
      cv_.notify_all();
    });
  }
  ~Events() { graph_.unsubscribe(id_); }
  // The first event after the first `after` ones that satisfies `what`, waiting up to 60 s.
  template <typename What>
  std::optional<GraphEvent> next(std::size_t& after, What what) {
    std::unique_lock lock(m_);
    std::optional<GraphEvent> found;
    cv_.wait_for(lock, std::chrono::seconds(60), [&] {
      for (; after < events_.size() && !found; ++after)
        if (what(events_[after])) found = events_[after];
      return found.has_value();
    });
    return found;
  }

 private:
  GraphOptimiser& graph_;
  std::uint64_t id_ = 0;
  std::mutex m_;
  std::condition_variable cv_;
  std::vector<GraphEvent> events_;
};

// The drive in a map database with the optimiser's worker running on it (debounce 10 ms) and every event it
// publishes collected; start() returns once the worker's start-up solve is done.
class Worker : public ::testing::Test {
 protected:
  void start(GraphOptimiserOptions o) {
    store = storage::MapStore::open(options(dir.file("map.db")));
    d = drive(*store);
    o.debounce = std::chrono::milliseconds(10);
    graph = std::make_unique<GraphOptimiser>(*store, o);
    events = std::make_unique<Events>(*graph);
    ASSERT_TRUE(graph->waitForVersion("m", 0, std::chrono::seconds(60)).has_value());
  }
  // The next event (after those already returned) that satisfies `what`, waiting up to 60 s.
  template <typename What>
  std::optional<GraphEvent> next(What what) {
    return events->next(seen, what);
  }

  TempDir dir;
  std::unique_ptr<storage::MapStore> store;
  Drive d;
  std::unique_ptr<GraphOptimiser> graph;  // after the store: stopped before it closes
  std::unique_ptr<Events> events;         // after the optimiser: unsubscribed before it stops
  std::size_t seen = 0;
};

bool localWith(const GraphEvent& e, std::int64_t loops) { return !e.global && e.loops == loops; }

// A loop arriving after a local solve is solved after the debounce, not held back until the global solve that
// the local one scheduled is due.
TEST_F(Worker, ALoopAfterALocalSolveIsNotHeldBackUntilTheGlobalSolve) {
  start(localOptions());  // the global solve an hour away
  addLoop(*store, d, 201);
  graph->loopsAdded("m");
  ASSERT_TRUE(next([](const GraphEvent& e) { return localWith(e, 40); }).has_value());
  addLoop(*store, d, 210);
  graph->loopsAdded("m");
  EXPECT_TRUE(next([](const GraphEvent& e) { return localWith(e, 41); }).has_value())
      << "the second loop waited for the global solve";
}

// The worker follows a local solve with a global one once global_interval_s has passed, with nothing new.
TEST_F(Worker, TheWorkerSolvesGloballySoonAfterALocalSolve) {
  auto o = localOptions();
  o.global_interval_s = 0.05;
  start(o);
  addLoop(*store, d, 201);
  graph->loopsAdded("m");
  ASSERT_TRUE(next([](const GraphEvent& e) { return localWith(e, 40); }).has_value());
  const auto settled = next([](const GraphEvent& e) { return e.global; });
  ASSERT_TRUE(settled.has_value()) << "no global solve followed the local one";
  EXPECT_EQ(settled->loops, 40);
  EXPECT_EQ(settled->free_nodes, 240);
}

// A loop the window cannot absorb (here 0.3 m off the truth: within the graduated solve's bound, beyond what
// ten nodes either side can take up) strains the local solve, and the global solve follows at once, not after
// global_interval_s (an hour).
TEST_F(Worker, AStrainedLocalSolveIsFollowedByAGlobalOneAtOnce) {
  start(localOptions());
  const Mat4d off = d.gt[201].inverse() * d.gt[81] * pose(0.0, 0.3, 0.0);
  ASSERT_GT(store->addLoop("m", {0, d.ids[201], d.ids[81], off, 0.8, 0.9, 0.02, 20}), 0);
  graph->loopsAdded("m");
  ASSERT_TRUE(next([](const GraphEvent& e) { return localWith(e, 40); }).has_value());
  const auto settled = next([](const GraphEvent& e) { return e.global; });
  ASSERT_TRUE(settled.has_value()) << "no global solve followed the strained local one";
  EXPECT_EQ(settled->loops, 40);
}

// A local solve stopped at its iteration bound goes on locally, with the same nodes free.
TEST(LocalSolve, AnUnconvergedLocalSolveIsContinuedLocally) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  auto o = localOptions();
  o.max_iterations = 1;
  GraphOptimiser graph(*store, o);
  const auto d = drive(*store);
  for (int k = 0; k < 30; ++k) graph.optimiseNow("m", GraphOptimiser::Scope::kGlobal);
  addLoop(*store, d, 201);
  const auto e = graph.optimiseNow("m");
  ASSERT_FALSE(e.failed) << e.error;
  ASSERT_FALSE(e.global);
  ASSERT_FALSE(e.converged);
  const auto c = graph.optimiseNow("m");  // what the worker's continuation does
  EXPECT_FALSE(c.global);
  EXPECT_EQ(c.free_nodes, e.free_nodes);
}

// A scan of lower sequence number than its session's first arrives late: it is placed in its session's frame
// (taken from the session's placed scans, not from itself), so a loop arriving with it agrees with the graph
// and is solved locally. Placed in its raw odometry frame, 50 m off, the loop was far off and solved globally.
TEST(LocalSolve, ALateFirstScanIsPlacedInItsSessionsFrame) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  GraphOptimiser graph(*store, localOptions());
  const auto d = drive(*store);
  ASSERT_FALSE(graph.optimiseNow("m").failed);
  // Robot x drives the first lap's scans 10..29 again, in an odometry frame of its own, with exact loops.
  const Mat4d unrelated = pose(1.0, 50.0, -20.0);
  std::map<int, std::int64_t> x;
  const auto addX = [&](int i) {
    const auto fp = storage::testing::randomFingerprint(900 + i);
    const Mat4d odometry = unrelated * d.gt[static_cast<std::size_t>(i)];
    x[i] = store->addScan(
        {.map = "m", .robot = "x", .session = "s", .seq = i, .odometry_pose = odometry, .fingerprint = &fp});
    ASSERT_GT(store->addLoop("m", {0, x[i], d.ids[static_cast<std::size_t>(i)], Mat4d::Identity(), 0.8, 0.9, 0.02, 20}),
              0);
  };
  for (int i = 11; i < 30; ++i) addX(i);
  ASSERT_FALSE(graph.optimiseNow("m").failed);
  addX(10);  // late, and first of its session
  const auto e = graph.optimiseNow("m");
  ASSERT_FALSE(e.failed) << e.error;
  EXPECT_FALSE(e.global);
  std::map<std::int64_t, Mat4d> poses;
  for (const auto& p : store->optimisedPoses("m", "", "", 0, 100000)) poses[p.scan_id] = p.pose;
  EXPECT_LT((poses.at(x[10]).block<3, 1>(0, 3) - poses.at(d.ids[10]).block<3, 1>(0, 3)).norm(), 0.2);
}

// A loop discounted earlier (false) does not strain every later local solve near it: only new loops and the
// window's boundary do.
TEST(LocalSolve, AnOldRejectedLoopDoesNotStrainLocalSolvesNearIt) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  const auto o = localOptions();
  auto g = solvedGraph(*store);
  // Scan 202 claimed to be 1 m from scan 22 (they are ~70 m apart): discounted by the global solve.
  const auto through = g.lastLoop();
  store->addLoop("m", {0, d.ids[202], d.ids[22], pose(0.0, 1.0, 0.0), 0.9, 0.9, 0.02, 30});
  absorbNewLoops(g, *store);
  const auto with_false = g.solve(o, through, true);
  ASSERT_TRUE(with_false.global);
  ASSERT_EQ(with_false.rejected_loops, 1);
  // A true loop whose window holds the false loop's end.
  const auto before_true = g.lastLoop();
  addLoop(*store, d, 204);
  absorbNewLoops(g, *store);
  const auto s = g.solve(o, before_true, true);
  EXPECT_FALSE(s.global);
  EXPECT_EQ(s.rejected_loops, 1);
  EXPECT_FALSE(s.strained);
}

// The worker adopts a background global solve of a copy of the graph: the copy's poses, with what arrived
// meanwhile still to solve; a copy of another graph is refused.
TEST(LocalSolve, AGlobalSolveOfACopyIsAdoptedWithWhatArrivedMeanwhileStillNew) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  const auto o = localOptions();
  auto g = solvedGraph(*store);
  MapGraph copy = g;
  addLoop(*store, d, 201);  // arrives while the copy is being solved
  copy.solve(o, copy.lastLoop(), false);
  absorbNewLoops(g, *store);
  const auto through = copy.lastLoop();
  EXPECT_FALSE(g.hasNew(g.lastLoop()));
  ASSERT_TRUE(g.adopt(copy));
  EXPECT_TRUE(g.hasNew(through));  // the new loop
  const auto poses = g.poses(), solved = copy.poses();
  for (std::size_t i = 0; i < solved.size(); ++i) EXPECT_EQ(poses[i].pose, solved[i].pose);
  const auto s = g.solve(o, through, true);
  EXPECT_FALSE(s.global);
  EXPECT_EQ(s.free_nodes, 2 * (2 * kWindow + 1));

  MapGraph other;  // another graph (its first node is a different scan) is not adopted
  auto nodes = store->graphNodes("m");
  nodes.erase(nodes.begin());
  ASSERT_TRUE(other.absorb("m", {}, nodes, {}));
  EXPECT_FALSE(g.adopt(other));
}

}  // namespace
}  // namespace sglc::posegraph
