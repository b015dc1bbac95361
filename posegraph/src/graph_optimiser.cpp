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
    : store_(store), options_(options) {
  const auto now = Clock::now();
  for (const auto& m : store_.listMaps())
    if (!store_.loops(m.name, 0, 1).empty()) due_[m.name] = now;
  worker_ = std::thread([this] { run(); });
}

GraphOptimiser::~GraphOptimiser() {
  stop();
  if (worker_.joinable()) worker_.join();
}

void GraphOptimiser::stop() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  changed_.notify_all();
}

bool GraphOptimiser::stopping() const {
  std::lock_guard lock(mutex_);
  return stop_;
}

void GraphOptimiser::loopsAdded(const std::string& map) {
  {
    std::lock_guard lock(mutex_);
    if (!due_.count(map)) due_[map] = Clock::now() + options_.debounce;
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
  std::unique_lock lock(mutex_);
  while (!stop_) {
    if (!forget_.empty()) {
      const auto names = std::exchange(forget_, {});
      lock.unlock();
      {
        std::lock_guard one(optimise_mutex_);
        for (const auto& name : names) graphs_.erase(name);
      }
      lock.lock();
      continue;
    }
    if (due_.empty()) {
      wake_.wait(lock);
      continue;
    }
    auto next =
        std::min_element(due_.begin(), due_.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
    if (next->second > Clock::now()) {
      wake_.wait_until(lock, next->second);
      continue;
    }
    const std::string map = next->first;
    due_.erase(next);
    lock.unlock();
    optimise(map);  // never throws: a failure becomes the map's failed event
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

GraphEvent GraphOptimiser::optimiseNow(const std::string& map) { return optimise(map); }

GraphEvent GraphOptimiser::optimise(const std::string& map) {
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
    return solve(map, map_id, gen);
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

GraphEvent GraphOptimiser::solve(const std::string& map, std::int64_t map_id, std::uint64_t generation) {
  const auto t0 = Clock::now();
  auto& slot = graphs_[map];
  {
    std::lock_guard lock(mutex_);
    if (stale_.erase(map) || slot.map_id != map_id) slot.graph.reset();
  }
  slot.map_id = map_id;
  if (!slot.graph) slot.graph = std::make_unique<MapGraph>();
  MapGraph& g = *slot.graph;

  // New rows since the last optimisation (after a deletion, all rows: the graph was dropped above). Loops are
  // read before scans: ingest stores a scan before its loops, so every loop read here finds its scans among the
  // nodes read after it (read the other way round, a scan and its loop stored between the two reads would give
  // a loop without its node, skipped and never read again).
  const auto loops = store_.loops(map, g.lastLoop());
  const auto nodes = store_.graphNodes(map, g.lastScan());
  // Loops with ids up to solved_through are reflected in the poses the solve starts from: the last solve's,
  // or, for a fresh graph (server start, after a deletion), the poses kept in the database, so that a restart
  // continues from where the last run stopped.
  std::int64_t solved_through = g.lastLoop();
  const bool fresh = g.empty();
  std::unordered_map<std::int64_t, Mat4d> kept;
  if (fresh) {
    for (const auto& p : store_.optimisedPoses(map, "", "", 0, std::numeric_limits<std::int64_t>::max()))
      if (!rigidMotionError(p.pose)) kept[p.scan_id] = orthonormalised(p.pose);  // else start from odometry
    solved_through = store_.optimisedThroughLoop(map);
  }
  const bool changed = g.absorb(map, loops, nodes, kept);
  // A solved graph with nothing new would only be solved again to the same poses: report the last event, no new
  // version (a request queued while an optimisation was running is often already covered by it).
  if (!fresh && !changed && g.converged()) {
    std::lock_guard lock(mutex_);
    const auto it = latest_.find(map);
    if (it != latest_.end()) return it->second;
  }

  const auto solution = g.solve(options_, solved_through);
  GraphEvent event;
  event.graph_version = store_.saveOptimised(map, map_id, g.poses(), g.frames(), g.lastLoop());
  event.loops = static_cast<std::int64_t>(g.loopCount());
  event.nodes = static_cast<std::int64_t>(g.nodeCount());
  event.rejected_loops = solution.rejected_loops;
  event.optimise_ms = msSince(t0);
  event.converged = solution.converged;
  event.map_id = map_id;
  g.countSolve(changed);  // new rows: a new problem
  continueIfUnconverged(map, g, generation);
  spdlog::info("{}", logging::logLine({{"event", "optimised"},
                                       {"map", map},
                                       {"version", event.graph_version},
                                       {"nodes", event.nodes},
                                       {"loops", event.loops},
                                       {"rejected", event.rejected_loops},
                                       {"iterations", solution.iterations},
                                       {"converged", event.converged},
                                       {"ms", std::round(event.optimise_ms * 10) / 10}}));
  publish(map, event, generation);
  return event;
}

// Stopped at a bound: carry on from here soon (the worker; optimiseNow callers see converged = false), but not
// forever on a graph that never meets Ceres' tolerances.
void GraphOptimiser::continueIfUnconverged(const std::string& map, const MapGraph& g, std::uint64_t generation) {
  if (g.converged() || g.continuations() >= options_.max_continuations) return;
  {
    std::lock_guard lock(mutex_);
    if (this->generation(map) != generation) return;  // deleted meanwhile
    if (!due_.count(map)) due_[map] = Clock::now() + options_.debounce;
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
