// Child process of the crash test: creates (or opens) map "m", prints "ready" on its own line once the map
// exists, then stores scans into it and prints "<scan id> <seq>" for each acknowledged scan on its own line
// (flushed) as soon as addScan returns. The parent waits for "ready" (and possibly some acknowledgements)
// before it kills the writer with SIGKILL at a random moment, so the map always exists when it checks.
// Usage: storage_crash_writer DB_PATH ROBOT FIRST_SEQ COUNT, or storage_crash_writer DB_PATH retire (below).
#include <cstdio>
#include <cstdlib>
#include <string>

#include "storage_test_util.hpp"

namespace {

// Retirement mode (storage_crash_writer DB_PATH retire): retires every scan of robot "b" of map "m" with one loop
// moved per retired scan (between the "a" scans of the same seq and the next), prints "ready" before it starts
// and "done" once retireScans returned; the parent kills it at a random moment in between (or after).
int retire(const std::string& path) {
  using namespace sglc::storage;
  StoreOptions opts;
  opts.path = path;
  opts.sync = StoreOptions::Sync::kFull;
  auto store = MapStore::open(opts);
  std::vector<std::int64_t> ids;
  std::vector<LoopRecord> moved;
  for (long seq = 0;; ++seq) {
    const auto b = store->findScan("m", "b", "run", seq);
    const auto a = store->findScan("m", "a", "run", seq), next = store->findScan("m", "a", "run", seq + 1);
    if (!b) break;
    ids.push_back(*b);
    if (a && next) moved.push_back({0, *next, *a, sglc::Mat4d::Identity(), 0.5, 0.6, 0.1, 9});
  }
  std::printf("ready\n");
  std::fflush(stdout);
  store->retireScans("m", ids, moved);
  std::printf("done\n");
  std::fflush(stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[2]) == "retire") return retire(argv[1]);
  if (argc != 5) return 2;
  using namespace sglc::storage;
  StoreOptions opts;
  opts.path = argv[1];
  opts.sync = StoreOptions::Sync::kFull;
  auto store = MapStore::open(opts);
  store->createMap("m", sglc::DescriptorLayout{}.scanDim());
  // Not an acknowledgement: the parent tells this line from "<id> <seq>" lines.
  std::printf("ready\n");
  std::fflush(stdout);
  const long first = std::atol(argv[3]), count = std::atol(argv[4]);
  for (long seq = first; seq < first + count; ++seq) {
    const auto fp = sglc::storage::testing::randomFingerprint(static_cast<std::uint64_t>(seq) * 31 + 7, 20);
    NewScan ns{.map = "m", .robot = argv[2], .session = "run", .seq = seq, .fingerprint = &fp};
    const auto id = store->addScan(ns);
    std::printf("%lld %ld\n", static_cast<long long>(id), seq);
    std::fflush(stdout);
  }
  return 0;
}
