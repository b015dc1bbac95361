// Keeps each map's pose graph optimised, off the request path (the graph itself and its solve: map_graph.hpp).
//
// Ingest records verified loops in the map database and calls loopsAdded(); a worker thread then reads the
// new graph rows (scans with odometry poses, loops), optimises the map's pose graph warm-started from its last
// solution, and writes the poses and session frames back to the database in one transaction. Bursts of loops
// are batched (one optimisation per `debounce`). On start every map that has loops is optimised once, so a
// restarted server serves the same poses and picks up loops recorded just before a crash.
//
// Several servers on one database (MapStore::shared): each map's graph is solved by the one that holds it
// (MapStore::claimGraph); the others follow its stored graph version and publish events for it, and every
// replica_poll_s each looks for loops other servers stored and tries to take over maps whose holder died.
//
// Nothing from outside can take the process down through here: scans whose odometry pose is not a rigid
// motion and loops with a damaged pose or information are left out of the graph (with a log line), the
// problem is checked to be finite before Ceres sees it, and a solve that fails or ends non-finite marks the
// map's graph failed (GraphEvent::failed) and keeps its last good poses, while every other map carries on.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>

#include "sglc/params.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::posegraph {

class MapGraph;

struct GraphEvent {
  std::int64_t graph_version = 0;
  std::int64_t loops = 0;
  std::int64_t nodes = 0;
  int rejected_loops = 0;
  double optimise_ms = 0;
  // The solve ended by convergence. False when it stopped at its iteration or time bound: the worker then
  // goes on from these poses (up to GraphOptimiserOptions::max_continuations times) until it converges.
  bool converged = false;
  // Every node was free. False: a local solve around the new loops and scans (the rest held fixed), of
  // `free_nodes` nodes; a global solve follows within GraphOptimiserOptions::global_interval_s, at once when
  // the local solve was strained (its window could not absorb the correction).
  bool global = true;
  std::int64_t free_nodes = 0;
  // The solve failed (non-finite or diverged): the map keeps its last good poses (graph_version is theirs) and
  // `error` says what happened. The next successful solve clears it.
  bool failed = false;
  std::string error;
  // The map was deleted: the last event listeners hear of it (never kept as latest()). A map created again under
  // the name is a new map with events of its own.
  bool deleted = false;
  std::int64_t map_id = 0;  // the map (storage::MapInfo::id) the event is about
};

struct GraphOptimiserOptions {
  std::chrono::milliseconds debounce{200};  // wait this long after a loop for more before optimising
  double max_seconds = 5.0;                 // per optimisation
  int max_iterations = 100;
  int max_continuations = 10;  // solves that go on from an unconverged one without new scans or loops
  double loss_scale = 1.0;     // Cauchy loss scale on whitened loop residuals
  // A loop whose probability of being true (the loop model's) is below this gets a narrower Cauchy loss: its
  // scale^2 shrinks with the probability's odds relative to this one's (posegraph/src/loop_weight.hpp). Loops
  // at or above it, and loops recorded without a probability, get loss_scale. 0 turns the probability off.
  // 0.9: with 0.95, true loops drawn from [0.9, 1] lost up to 1.7 % ATE on KITTI 08 for no gain against false
  // ones (sglc-bench-false-loops, docs/PERFORMANCE.md); to be set anew from the loop model's own distribution.
  double trusted_probability = 0.9;
  // Bounded cost per loop event: a solve frees only the scans added since the last one and this many nodes on
  // either side (in their session) of each end of every new loop, the rest held fixed (0: every solve is
  // global). A new loop far off the current poses, or a window over half the graph, still solves globally.
  int local_window = 100;
  // After a local solve, the whole graph is solved again within this many seconds (one global solve for
  // however many local ones came meanwhile), so that corrections spread beyond the windows; at once (in the
  // background, one at a time) after a local solve that left an edge at its window's boundary or a new loop in it
  // beyond the 99.9 % point of its error.
  double global_interval_s = 30.0;
  // With a database shared by several servers (replicas): how often each looks for loops the others stored,
  // and whether the replica that solves a map's graph is still alive (else it takes the map over).
  double replica_poll_s = 2.0;
  // Odometry between consecutive scans of a session: per-axis sigmas growing with the distance driven. The
  // defaults suit LiDAR odometry that drifts about 1 % in translation and 0.005 deg per metre in heading.
  double odometry_sigma_m = 0.01, odometry_sigma_per_m = 0.015;
  double odometry_sigma_deg = 0.005, odometry_sigma_deg_per_m = 0.005;
  // Loops: the registration's information with this floor covariance added (per axis), or, for loops recorded
  // without information, a per-axis sigma from the refinement's RMSE, at least these.
  double loop_sigma_m = 0.05, loop_sigma_deg = 0.3;
};

// The options in the settings registry: the `pose_graph:` section of the server's configuration.
const params::Table<GraphOptimiserOptions>& graphParams();

class GraphOptimiser {
 public:
  GraphOptimiser(storage::MapStore& store, GraphOptimiserOptions options);
  ~GraphOptimiser();  // stops the worker (an optimisation in progress finishes first)
  GraphOptimiser(const GraphOptimiser&) = delete;
  GraphOptimiser& operator=(const GraphOptimiser&) = delete;

  // New loops (or scans) in `map`: optimise soon.
  void loopsAdded(const std::string& map);
  // Scans (and with them loops) of `map` were deleted: rebuild its graph from the database and optimise now.
  void scansRemoved(const std::string& map);
  // `map` (of id map_id) was deleted: drop its pending solve and its last event, and tell listeners (an event
  // with `deleted`). A solve of it still running publishes nothing; a map created later under the name starts
  // with a graph rebuilt from the database.
  void mapDeleted(const std::string& map, std::int64_t map_id);
  // The latest event of the map once its graph version exceeds `after`, waiting at most `timeout`; nullopt on
  // timeout or when stopping.
  std::optional<GraphEvent> waitForVersion(const std::string& map, std::int64_t after,
                                           std::chrono::milliseconds timeout);
  // Optimises now on the calling thread (tests, tools); returns the event. A graph already solved to
  // convergence with no new scans or loops is not solved again: its last event comes back, no new version.
  // kAuto solves locally or globally as the worker would; kGlobal solves the whole graph (and counts as the
  // pending global solve).
  enum class Scope { kAuto, kGlobal };
  GraphEvent optimiseNow(const std::string& map, Scope scope = Scope::kAuto);
  // The map's last event (failed or not), if any.
  std::optional<GraphEvent> latest(const std::string& map) const;
  // Listeners get every new event (a new graph version, a failure, or the map's deletion) of every map, on the
  // thread that made it, in order. They must not block. After unsubscribe() returns, the listener is never called
  // again.
  using Listener = std::function<void(const std::string& map, const GraphEvent& event)>;
  std::uint64_t subscribe(Listener listener);
  void unsubscribe(std::uint64_t id);
  // Ends waits and the worker.
  void stop();
  bool stopping() const;

  // What it was made with (edge weights, windows): exports weigh edges as its solves do.
  const GraphOptimiserOptions& options() const { return options_; }

 private:
  void run();
  GraphEvent optimise(const std::string& map, Scope scope);
  // A map another server solves: drop our graph (a takeover starts from the stored poses) and publish the
  // stored graph version when it moved.
  GraphEvent follow(const std::string& map, std::int64_t map_id, std::uint64_t generation);
  // Shared databases: queue the maps with loops this server has not solved (other servers' loops, or maps
  // another server holds, to follow them and take them over when their holder dies), rebuild graphs whose
  // sessions or robots another server deleted, and announce maps another server deleted.
  void pollMaps();
  GraphEvent solve(const std::string& map, std::int64_t map_id, std::uint64_t generation, Scope scope);
  // The map's in-memory graph, rebuilt when stale or when the name is a new map.
  MapGraph& graphOf(const std::string& map, std::int64_t map_id);
  struct Rows {
    bool fresh = false, changed = false;
    std::int64_t solved_through = 0;  // loops up to this id are reflected in the graph's poses
  };
  Rows readRows(const std::string& map, MapGraph& g);
  void logEvent(const std::string& map, const GraphEvent& event, std::size_t iterations) const;
  // Background global solves (background_global.cpp): the worker hands a copy of the map's graph to a thread
  // of their own, and adopts the solved poses on its next solve of the map, solving around whatever arrived
  // meanwhile. Returns the last loop the adopted solve accounts for, or nullopt when there is none to adopt.
  void startGlobal(const std::string& map, std::uint64_t generation);
  std::optional<std::int64_t> adoptGlobal(const std::string& map, MapGraph& g);
  void runGlobal();
  // Solve `map` by `at` at the latest (a time already sooner stays). mutex_ held.
  void dueBy(const std::string& map, std::chrono::steady_clock::time_point at);
  // Whether the map's pending global solve is due (then it starts in the background).
  bool globalDue(const std::string& map) const;
  // After a local solve: make sure a global one follows within global_interval_s; after a global one: none is
  // pending.
  void scheduleGlobal(const std::string& map, std::uint64_t generation, bool was_global, bool strained);
  // After an unconverged solve: solve the map again soon, unless it has been continued often enough.
  void continueIfUnconverged(const std::string& map, const MapGraph& graph, std::uint64_t generation);
  // Publishes the event of a solve begun at `generation` of the name, unless the map was deleted since.
  void publish(const std::string& map, const GraphEvent& event, std::uint64_t generation);
  std::uint64_t generation(const std::string& map) const;  // mutex_ held
  // Whether `map` is still the map of id `map_id` (0: any map of that name); true when the database fails.
  bool sameMap(const std::string& map, std::int64_t map_id) const;

  storage::MapStore& store_;
  GraphOptimiserOptions options_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;                                      // the worker
  std::condition_variable changed_;                                   // watchers
  std::map<std::string, std::chrono::steady_clock::time_point> due_;  // maps to optimise, and when
  std::map<std::string, GraphEvent> latest_;
  std::map<std::string, std::chrono::steady_clock::time_point> global_at_;  // pending global solves, and when
  std::set<std::string> stale_;                     // maps whose in-memory graph must be rebuilt
  std::set<std::string> forget_;                    // deleted maps whose in-memory graph the worker drops
  std::map<std::string, std::uint64_t> deletions_;  // per name: how often a map of it was deleted
  struct Slot {
    std::int64_t map_id = 0;  // the map (MapInfo::id) the graph was built from: a name created again is a new map
    std::unique_ptr<MapGraph> graph;
    // Changes when the graph is rebuilt or solved globally in place: a background solve begun before is stale.
    std::uint64_t lineage = 0;
  };
  std::map<std::string, Slot> graphs_;  // only the worker / optimiseNow touch these
  std::set<std::string> held_;          // maps whose graph this server solves (shared databases); as graphs_
  std::map<std::string, std::int64_t> deletions_seen_;  // MapInfo::deletions at the last poll; as graphs_
  const bool shared_;
  std::uint64_t next_lineage_ = 0;
  struct GlobalJob {
    std::string map;
    std::uint64_t generation = 0, lineage = 0;
    std::unique_ptr<MapGraph> graph;  // a copy of the map's graph, solved in place
    std::string error;                // why the solve failed
    double ms = 0;
  };
  std::vector<GlobalJob> global_todo_;            // mutex_ held
  std::map<std::string, GlobalJob> global_done_;  // mutex_ held
  std::set<std::string> global_running_;          // mutex_ held: handed over and not yet done
  std::condition_variable global_wake_;
  std::atomic<bool> cancel_{false};  // stops a background solve at its next iteration (on stop())
  std::thread global_worker_;
  std::mutex optimise_mutex_;  // one optimisation at a time
  bool stop_ = false;
  std::mutex listeners_mutex_;  // held while listeners run
  std::map<std::uint64_t, Listener> listeners_;
  std::uint64_t next_listener_ = 1;
  std::thread worker_;
};

}  // namespace sglc::posegraph
