#include "sglc/posegraph/graph_optimiser.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <utility>

#include "map_graph.hpp"
#include "sglc/elapsed.hpp"
#include "sglc/log/log_line.hpp"
#include "sglc/rigid.hpp"

namespace sglc::posegraph {

GraphOptimiser::GraphOptimiser(storage::MapStore& store, GraphOptimiserOptions options)
    : store_(store), options_(options), shared_(store.shared()) {
  const auto now = Clock::now();
  for (const auto& m : store_.listMaps())
    if (!store_.loops(m.name, 0, 1).empty()) due_[m.name] = now;
  worker_ = std::thread([this] { run(); });
  global_worker_ = std::thread([this] { runGlobal(); });
}

GraphOptimiser::~GraphOptimiser() {
  stop();
  if (worker_.joinable()) worker_.join();
  if (global_worker_.joinable()) global_worker_.join();
}

void GraphOptimiser::stop() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  cancel_ = true;  // a background global solve stops at its next iteration
  wake_.notify_all();
  changed_.notify_all();
  global_wake_.notify_all();
}

bool GraphOptimiser::stopping() const {
  std::lock_guard lock(mutex_);
  return stop_;
}

void GraphOptimiser::loopsAdded(const std::string& map) {
  {
    std::lock_guard lock(mutex_);
    dueBy(map, Clock::now() + options_.debounce);  // sooner than a global solve scheduled for it
  }
  wake_.notify_all();
}

void GraphOptimiser::scansRemoved(const std::string& map) {
  {
    std::lock_guard lock(mutex_);
    stale_.insert(map);
    due_[map] = Clock::now();
  }
  wake_.notify_all();
}

void GraphOptimiser::mapDeleted(const std::string& map, std::int64_t map_id) {
  {
    std::lock_guard lock(mutex_);
    ++deletions_[map];  // solves begun before now publish nothing
    due_.erase(map);
    global_at_.erase(map);
    global_done_.erase(map);
    latest_.erase(map);
    stale_.insert(map);
    forget_.insert(map);  // the worker frees the map's graph (it owns graphs_)
  }
  wake_.notify_all();
  GraphEvent gone;
  gone.deleted = true;
  gone.map_id = map_id;
  std::lock_guard lock(listeners_mutex_);
  for (const auto& [id, listener] : listeners_) listener(map, gone);
}

std::optional<GraphEvent> GraphOptimiser::waitForVersion(const std::string& map, std::int64_t after,
                                                         std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  const bool ready = changed_.wait_for(lock, timeout, [&] {
    if (stop_) return true;
    const auto it = latest_.find(map);
    return it != latest_.end() && it->second.graph_version > after;
  });
  const auto it = latest_.find(map);
  if (!ready || stop_ || it == latest_.end() || it->second.graph_version <= after) return std::nullopt;
  return it->second;
}

void GraphOptimiser::run() {
  const auto poll_every = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(std::max(0.05, options_.replica_poll_s)));
  auto next_poll = Clock::now() + poll_every;
  std::unique_lock lock(mutex_);
  while (!stop_) {
    if (shared_ && Clock::now() >= next_poll) {
      lock.unlock();
      pollMaps();
      lock.lock();
      next_poll = Clock::now() + poll_every;
      continue;
    }
    if (!forget_.empty()) {
      const auto names = std::exchange(forget_, {});
      lock.unlock();
      {
        std::lock_guard one(optimise_mutex_);
        for (const auto& name : names) {
          graphs_.erase(name);
          held_.erase(name);
          deletions_seen_.erase(name);
        }
      }
      lock.lock();
      continue;
    }
    if (due_.empty()) {
      if (shared_)
        wake_.wait_until(lock, next_poll);
      else
        wake_.wait(lock);
      continue;
    }
    auto next =
        std::min_element(due_.begin(), due_.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
    if (next->second > Clock::now()) {
      // A copy: wait_until reads its deadline after waking, and mapDeleted may have erased the entry by then.
      const Clock::time_point deadline = shared_ ? std::min(next->second, next_poll) : next->second;
      wake_.wait_until(lock, deadline);
      continue;
    }
    const std::string map = next->first;
    due_.erase(next);
    lock.unlock();
    optimise(map, Scope::kAuto);  // never throws: a failure becomes the map's failed event
    lock.lock();
  }
}

bool GraphOptimiser::sameMap(const std::string& map, std::int64_t map_id) const {
  try {
    const auto info = store_.findMap(map);
    return info && (map_id == 0 || info->id == map_id);
  } catch (const std::exception&) {
    return true;  // the database failed: report the failure as usual
  }
}

GraphEvent GraphOptimiser::optimiseNow(const std::string& map, Scope scope) { return optimise(map, scope); }

GraphEvent GraphOptimiser::optimise(const std::string& map, Scope scope) {
  std::lock_guard one(optimise_mutex_);
  std::uint64_t gen = 0;
  {
    std::lock_guard lock(mutex_);
    gen = generation(map);
  }
  std::int64_t map_id = 0;
  try {
    const auto info = store_.findMap(map);
    if (!info) {  // deleted before the solve began: nothing to report about a map that is gone
      GraphEvent event;
      event.failed = true;
      event.error = "the map was deleted";
      return event;
    }
    map_id = info->id;
    if (shared_) {
      const auto claim = store_.claimGraph(map_id);
      if (claim == storage::MapStore::GraphClaim::kElsewhere) return follow(map, map_id, gen);
      // Just taken (first solve here, or the lock was lost and taken again): another server may have solved the
      // map meanwhile, so the graph is rebuilt from the stored rows and poses.
      if (claim == storage::MapStore::GraphClaim::kTaken) graphs_.erase(map);
      if (held_.insert(map).second)
        spdlog::info("{}", logging::logLine({{"event", "graph_owner"}, {"map", map}, {"held", true}}));
    }
    return solve(map, map_id, gen, scope);
  } catch (const std::exception& e) {
    // The map keeps its last good poses; its graph is rebuilt from the database on the next attempt.
    graphs_.erase(map);
    GraphEvent event = latest(map).value_or(GraphEvent{});
    // Deleted while it was being solved (and perhaps created again under its name, a new map with its own
    // events): nothing to report about a map that is gone.
    if (!sameMap(map, map_id)) {
      event.failed = true;
      event.error = "the map was deleted";
      return event;
    }
    try {
      if (!event.graph_version) event.graph_version = store_.graphVersion(map);
    } catch (const std::exception&) {
      // the database failed too: the event says 0
    }
    event.failed = true;
    event.converged = false;
    event.error = e.what();
    event.map_id = map_id;
    spdlog::error(
        "{}",
        logging::logLine(
            {{"event", "optimise_failed"}, {"map", map}, {"version", event.graph_version}, {"error", event.error}}));
    publish(map, event, gen);
    return event;
  }
}

GraphEvent GraphOptimiser::follow(const std::string& map, std::int64_t map_id, std::uint64_t generation) {
  graphs_.erase(map);
  if (held_.erase(map)) spdlog::warn("{}", logging::logLine({{"event", "graph_owner"}, {"map", map}, {"held", false}}));
  GraphEvent event = latest(map).value_or(GraphEvent{});
  const auto version = store_.graphVersion(map);
  if (version == event.graph_version && event.map_id == map_id) return event;
  // The stored version only: nodes, loops and the solve's details are in the holder's own events.
  event = GraphEvent{};
  event.graph_version = version;
  event.map_id = map_id;
  event.converged = true;
  publish(map, event, generation);
  return event;
}

void GraphOptimiser::pollMaps() {
  std::vector<storage::MapInfo> maps;
  try {
    maps = store_.listMaps();
  } catch (const std::exception&) {
    return;  // the database is unreachable: the next poll tries again
  }
  // Maps deleted through another server (gone, or their name now another map's): announced here too.
  std::vector<std::pair<std::string, std::int64_t>> gone;
  {
    std::lock_guard lock(mutex_);
    for (const auto& known : latest_) {
      const auto it = std::find_if(maps.begin(), maps.end(), [&](const auto& m) { return m.name == known.first; });
      const auto id = known.second.map_id;
      if (id != 0 && (it == maps.end() || it->id != id)) gone.emplace_back(known.first, id);
    }
  }
  for (const auto& [name, id] : gone) mapDeleted(name, id);
  std::vector<std::string> todo, removed;
  for (const auto& m : maps) {
    try {
      std::int64_t after = 0;
      bool built = false;
      {
        std::lock_guard one(optimise_mutex_);
        const auto it = graphs_.find(m.name);
        built = it != graphs_.end() && it->second.graph && it->second.map_id == m.id;
        if (built) after = it->second.graph->lastLoop();
        // Sessions or robots deleted through another server: the graph may hold their scans.
        auto& seen = deletions_seen_[m.name];
        if (built && m.deletions != seen) removed.push_back(m.name);
        seen = m.deletions;
      }
      // Built and solved up to date: nothing to do. Not built here: follow it (and take it over if its holder
      // died) once it has a graph.
      if (!store_.loops(m.name, after, 1).empty() || (!built && store_.graphVersion(m.name) > 0))
        todo.push_back(m.name);
    } catch (const std::exception&) {
      // deleted meanwhile, or the database failed: the next poll sees
    }
  }
  for (const auto& map : removed) scansRemoved(map);
  {
    std::lock_guard lock(mutex_);
    for (const auto& map : todo) dueBy(map, Clock::now() + options_.debounce);
  }
  wake_.notify_all();
}

MapGraph& GraphOptimiser::graphOf(const std::string& map, std::int64_t map_id) {
  auto& slot = graphs_[map];
  {
    std::lock_guard lock(mutex_);
    if (stale_.erase(map) || slot.map_id != map_id) slot.graph.reset();
  }
  slot.map_id = map_id;
  if (!slot.graph) {
    slot.graph = std::make_unique<MapGraph>();
    slot.lineage = ++next_lineage_;  // a global solve of the graph it replaces is not for this one
  }
  return *slot.graph;
}

GraphOptimiser::Rows GraphOptimiser::readRows(const std::string& map, MapGraph& g) {
  // New rows since the last optimisation (after a deletion, all rows: the graph was dropped). Loops are read
  // before scans: ingest stores a scan before its loops, so every loop read here finds its scans among the
  // nodes read after it (read the other way round, a scan and its loop stored between the two reads would give
  // a loop without its node, skipped and never read again).
  const auto loops = store_.loops(map, g.lastLoop());
  const auto nodes = store_.graphNodes(map, g.lastScan());
  // Loops with ids up to solved_through are reflected in the poses the solve starts from: the last solve's,
  // or, for a fresh graph (server start, after a deletion), the poses kept in the database, so that a restart
  // continues from where the last run stopped.
  Rows rows;
  rows.solved_through = g.lastLoop();
  rows.fresh = g.empty();
  std::unordered_map<std::int64_t, Mat4d> kept;
  if (rows.fresh) {
    for (const auto& p : store_.optimisedPoses(map, "", "", 0, std::numeric_limits<std::int64_t>::max()))
      if (!rigidMotionError(p.pose)) kept[p.scan_id] = orthonormalised(p.pose);  // else start from odometry
    rows.solved_through = store_.optimisedThroughLoop(map);
  }
  rows.changed = g.absorb(map, loops, nodes, kept);
  return rows;
}

GraphEvent GraphOptimiser::solve(const std::string& map, std::int64_t map_id, std::uint64_t generation, Scope scope) {
  const auto t0 = Clock::now();
  MapGraph& g = graphOf(map, map_id);
  auto rows = readRows(map, g);
  // A global solve finished in the background since: its poses, and what arrived meanwhile solved around it.
  const auto adopted = adoptGlobal(map, g);
  if (adopted) rows.solved_through = *adopted;
  const bool global = rows.fresh || scope == Scope::kGlobal;
  const bool background = !global && !adopted && globalDue(map);
  // A solved graph with nothing new would only be solved again to the same poses: report the last event, no new
  // version (a request queued while an optimisation was running is often already covered by it). A global
  // solve due for it (converged or not) starts in the background instead.
  if (!rows.fresh && !rows.changed && !global && !adopted && (g.converged() || background)) {
    if (background) startGlobal(map, generation);
    std::lock_guard lock(mutex_);
    const auto it = latest_.find(map);
    if (it != latest_.end()) return it->second;
  }

  // After an adopted global solve with nothing new, there is nothing to solve: every pose is new.
  const bool settled = adopted && !g.hasNew(rows.solved_through);
  auto solution = settled ? g.settledSolution() : g.solve(options_, rows.solved_through, !global);
  const bool whole = solution.global;  // every pose is now a global solve's (of everything new too)
  if (whole && !settled) graphs_[map].lineage = ++next_lineage_;  // a background copy from before is outdated
  if (adopted) {  // every pose is the background solve's, what arrived meanwhile solved around them
    solution.global = true;
    solution.free_nodes = g.nodeCount();
  }
  GraphEvent event;
  // A local solve moved only its free nodes: only theirs are written.
  event.graph_version =
      store_.saveOptimised(map, map_id, solution.global ? g.poses() : g.movedPoses(), g.frames(), g.lastLoop());
  event.loops = static_cast<std::int64_t>(g.loopCount());
  event.nodes = static_cast<std::int64_t>(g.nodeCount());
  event.rejected_loops = solution.rejected_loops;
  event.optimise_ms = msSince(t0);
  event.converged = solution.converged;
  event.global = solution.global;
  event.free_nodes = static_cast<std::int64_t>(solution.free_nodes);
  event.map_id = map_id;
  g.countSolve(rows.changed);  // new rows: a new problem
  // An adopted global solve that stopped at its bound goes on in the background, not on this thread.
  const bool hand_back = settled && !solution.converged && g.continuations() < options_.max_continuations;
  if (background) startGlobal(map, generation);
  // Whole: no global solve pending; else one follows within the interval (at once when strained or handed back).
  scheduleGlobal(map, generation, whole && !hand_back, solution.strained || hand_back);
  if (!settled) continueIfUnconverged(map, g, generation);
  logEvent(map, event, solution.iterations);
  publish(map, event, generation);
  return event;
}

void GraphOptimiser::logEvent(const std::string& map, const GraphEvent& event, std::size_t iterations) const {
  spdlog::info("{}", logging::logLine({{"event", "optimised"},
                                       {"map", map},
                                       {"version", event.graph_version},
                                       {"nodes", event.nodes},
                                       {"loops", event.loops},
                                       {"rejected", event.rejected_loops},
                                       {"iterations", iterations},
                                       {"converged", event.converged},
                                       {"global", event.global},
                                       {"free", event.free_nodes},
                                       {"ms", std::round(event.optimise_ms * 10) / 10}}));
}

// Stopped at a bound: carry on from here soon (the worker; optimiseNow callers see converged = false), but not
// forever on a graph that never meets Ceres' tolerances.
void GraphOptimiser::continueIfUnconverged(const std::string& map, const MapGraph& g, std::uint64_t generation) {
  if (g.converged() || g.continuations() >= options_.max_continuations) return;
  {
    std::lock_guard lock(mutex_);
    if (this->generation(map) != generation) return;  // deleted meanwhile
    dueBy(map, Clock::now() + options_.debounce);
  }
  wake_.notify_all();
}

void GraphOptimiser::dueBy(const std::string& map, Clock::time_point at) {
  const auto due = due_.find(map);
  if (due == due_.end() || due->second > at) due_[map] = at;
}

bool GraphOptimiser::globalDue(const std::string& map) const {
  std::lock_guard lock(mutex_);
  const auto it = global_at_.find(map);
  return it != global_at_.end() && it->second <= Clock::now();
}

// A global solve settles what local ones left pending; after a local one, the next global solve is due at most
// global_interval_s later (not pushed back by further local ones: the rate is bounded, not starved).
void GraphOptimiser::scheduleGlobal(const std::string& map, std::uint64_t generation, bool was_global, bool strained) {
  {
    std::lock_guard lock(mutex_);
    if (this->generation(map) != generation) return;  // deleted meanwhile
    if (was_global) {
      global_at_.erase(map);
      return;
    }
    // Strained: the local window could not absorb the correction, so the whole graph is due now (still one
    // global solve at a time).
    const auto delay = strained ? 0.0 : options_.global_interval_s;
    const auto soon = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(delay));
    auto& at = global_at_.try_emplace(map, soon).first->second;
    at = std::min(at, soon);
    dueBy(map, at);
  }
  wake_.notify_all();
}

std::uint64_t GraphOptimiser::generation(const std::string& map) const {
  const auto it = deletions_.find(map);
  return it == deletions_.end() ? 0 : it->second;
}

// Listeners hear events in the order they happen: the check against a deletion and the calls happen under
// listeners_mutex_, which mapDeleted takes (after counting the deletion) to announce it.
void GraphOptimiser::publish(const std::string& map, const GraphEvent& event, std::uint64_t generation) {
  std::lock_guard order(listeners_mutex_);
  {
    std::lock_guard lock(mutex_);
    if (this->generation(map) != generation) return;  // the map was deleted since the solve began
    latest_[map] = event;
  }
  changed_.notify_all();
  for (const auto& [id, listener] : listeners_) listener(map, event);
}

std::optional<GraphEvent> GraphOptimiser::latest(const std::string& map) const {
  std::lock_guard lock(mutex_);
  const auto it = latest_.find(map);
  if (it == latest_.end()) return std::nullopt;
  return it->second;
}

std::uint64_t GraphOptimiser::subscribe(Listener listener) {
  std::lock_guard lock(listeners_mutex_);
  const auto id = next_listener_++;
  listeners_[id] = std::move(listener);
  return id;
}

void GraphOptimiser::unsubscribe(std::uint64_t id) {
  std::lock_guard lock(listeners_mutex_);
  listeners_.erase(id);
}

}  // namespace sglc::posegraph
