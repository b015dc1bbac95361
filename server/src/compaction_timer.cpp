#include "compaction_timer.hpp"

#include <spdlog/spdlog.h>

#include <chrono>

#include "sglc/log/log_line.hpp"

namespace sglc::server {

void logCompaction(const std::string& map, const closing::CompactionReport& r) {
  spdlog::info("{}", logging::logLine({{"event", "compacted"},
                                       {"map", map},
                                       {"placed", r.placed},
                                       {"promoted", r.promoted},
                                       {"demoted", r.demoted},
                                       {"retired", r.retired},
                                       {"bytes", r.retired_bytes},
                                       {"loops_moved", r.loops_moved},
                                       {"loops_dropped", r.loops_dropped},
                                       {"places", r.places},
                                       {"versions", r.versions}}));
}

CompactionTimer::CompactionTimer(storage::MapStore& store, closing::LifelongOptions policy,
                                 closing::OdometryNoise noise, Done done)
    : store_(store), policy_(policy), noise_(noise), done_(std::move(done)) {
  if (policy_.enabled() && policy_.compact_interval_s > 0) thread_ = std::thread([this] { run(); });
}

CompactionTimer::~CompactionTimer() {
  {
    const std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void CompactionTimer::run() {
  const auto interval = std::chrono::duration<double>(policy_.compact_interval_s);
  std::unique_lock lock(mutex_);
  for (;;) {
    if (wake_.wait_for(lock, interval, [this] { return stop_; })) return;
    lock.unlock();
    compactAll();
    lock.lock();
  }
}

void CompactionTimer::compactAll() {
  std::vector<storage::MapInfo> maps;
  try {
    maps = store_.listMaps();
  } catch (const std::exception& e) {
    done_("", {}, e.what());
    return;
  }
  for (const auto& map : maps) {
    {
      const std::lock_guard lock(mutex_);
      if (stop_) return;
    }
    try {
      const double now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
      const auto r = closing::compact(store_, map.name, policy_, noise_, now);
      if (r.placed + r.promoted + r.demoted + r.retired > 0) done_(map.name, r, "");
    } catch (const storage::StorageError& e) {
      // A map deleted meanwhile is no failure; anything else is reported and tried again next time.
      if (e.code() != storage::StorageError::Code::kNotFound) done_(map.name, {}, e.what());
    }
  }
}

std::unique_ptr<CompactionTimer> startCompactionTimer(storage::MapStore& store, closing::LifelongOptions policy,
                                                      closing::OdometryNoise noise, posegraph::GraphOptimiser& graph) {
  return std::make_unique<CompactionTimer>(
      store, policy, noise,
      [&graph](const std::string& map, const closing::CompactionReport& r, const std::string& error) {
        if (!error.empty()) {
          spdlog::warn("{}", logging::logLine({{"event", "compaction_failed"}, {"map", map}, {"error", error}}));
          return;
        }
        if (r.retired > 0) graph.scansRemoved(map);
        logCompaction(map, r);
      });
}

}  // namespace sglc::server
