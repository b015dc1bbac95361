// GraphOptimiser's global solves in the background: a copy of the map's graph is solved on a thread of its own
// while the worker goes on with local solves; the worker then adopts the result (see graph_optimiser.hpp).
#include <spdlog/spdlog.h>

#include <cmath>

#include "map_graph.hpp"
#include "sglc/elapsed.hpp"
#include "sglc/log/log_line.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"

namespace sglc::posegraph {

void GraphOptimiser::startGlobal(const std::string& map, std::uint64_t generation) {
  {
    std::lock_guard lock(mutex_);
    if (global_running_.count(map) || this->generation(map) != generation) return;  // before copying the graph
  }
  const auto& slot = graphs_.at(map);
  GlobalJob job{map, generation, slot.lineage, std::make_unique<MapGraph>(*slot.graph), {}, 0};
  {
    std::lock_guard lock(mutex_);
    if (global_running_.count(map) || this->generation(map) != generation) return;
    global_at_.erase(map);  // handed over
    global_running_.insert(map);
    global_todo_.push_back(std::move(job));
  }
  global_wake_.notify_all();
}

void GraphOptimiser::runGlobal() {
  std::unique_lock lock(mutex_);
  while (!stop_) {
    if (global_todo_.empty()) {
      global_wake_.wait(lock);
      continue;
    }
    auto job = std::move(global_todo_.front());
    global_todo_.erase(global_todo_.begin());
    lock.unlock();
    const auto t0 = Clock::now();
    try {
      job.graph->solve(options_, job.graph->lastLoop(), false, &cancel_);
    } catch (const std::exception& e) {
      job.error = e.what();
    }
    job.ms = msSince(t0);
    lock.lock();
    global_running_.erase(job.map);
    if (stop_ || generation(job.map) != job.generation) continue;  // stopping, or the map was deleted
    const auto map = job.map;
    global_done_.insert_or_assign(map, std::move(job));
    due_[map] = Clock::now();  // the worker adopts it next
    wake_.notify_all();
  }
}

std::optional<std::int64_t> GraphOptimiser::adoptGlobal(const std::string& map, MapGraph& g) {
  GlobalJob job;
  {
    std::lock_guard lock(mutex_);
    const auto it = global_done_.find(map);
    if (it == global_done_.end()) return std::nullopt;
    job = std::move(it->second);
    global_done_.erase(it);
  }
  std::string outcome = "adopted";
  if (!job.error.empty())
    outcome = "failed: " + job.error;  // the map keeps its poses; the next local solve schedules another
  else if (job.lineage != graphs_.at(map).lineage)
    outcome = "outdated";  // the graph was rebuilt or solved globally since the copy
  else if (!g.adopt(*job.graph))
    outcome = "outdated";
  spdlog::info("{}", logging::logLine({{"event", "global_solve"},
                                       {"map", map},
                                       {"nodes", job.graph->nodeCount()},
                                       {"outcome", outcome},
                                       {"ms", std::round(job.ms * 10) / 10}}));
  if (outcome != "adopted") {
    // Local solves since the last global one still want one (those made while this ran have scheduled theirs).
    scheduleGlobal(map, job.generation, false, false);
    return std::nullopt;
  }
  return job.graph->lastLoop();
}

}  // namespace sglc::posegraph
