// The server's own compaction of lifelong maps (docs/LIFELONG.md): every map.compact_interval_s it compacts
// every map, so a session's surplus scans retire once it has ended and its retention has passed without anyone
// running `sglc compact`. Nothing runs with the policy off. Servers sharing a PostgreSQL map each run it: their
// retirements are serialised by the store's write lock and idempotent (scans already gone are skipped, a moved
// loop whose pair has a loop is not added twice).
#pragma once

#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "sglc/closing/compaction.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::server {

// The log line of one compaction: {"event":"compacted", "map", what it placed, promoted, demoted, retired, ...}.
void logCompaction(const std::string& map, const closing::CompactionReport& r);

class CompactionTimer {
 public:
  // Told of each compaction that changed anything (placed, promoted, demoted, retired), or of its failure (error
  // non-empty).
  using Done = std::function<void(const std::string& map, const closing::CompactionReport&, const std::string& error)>;

  CompactionTimer(storage::MapStore& store, closing::LifelongOptions policy, closing::OdometryNoise noise, Done done);
  ~CompactionTimer();  // stops; a compaction in progress finishes first
  CompactionTimer(const CompactionTimer&) = delete;
  CompactionTimer& operator=(const CompactionTimer&) = delete;

 private:
  void run();
  void compactAll();

  storage::MapStore& store_;
  const closing::LifelongOptions policy_;
  const closing::OdometryNoise noise_;
  const Done done_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  std::thread thread_;
};

// The server's timer: retired scans leave `graph` at once; each compaction that changed anything, or failed, is
// logged.
std::unique_ptr<CompactionTimer> startCompactionTimer(storage::MapStore& store, closing::LifelongOptions policy,
                                                      closing::OdometryNoise noise, posegraph::GraphOptimiser& graph);

}  // namespace sglc::server
