// Crash safety and concurrency of the map store.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <map>
#include <random>
#include <sstream>
#include <thread>

#include "storage_test_util.hpp"

#ifndef SGLC_CRASH_WRITER
#error "SGLC_CRASH_WRITER must name the crash writer executable"
#endif

namespace sglc::storage {
namespace {

using testing::options;
using testing::randomFingerprint;
using testing::TempDir;

// Runs the writer, kills it with SIGKILL after `delay_ms`, and returns the (id, seq) pairs it acknowledged.
std::vector<std::pair<std::int64_t, long>> runAndKill(const std::string& db, long first, int delay_ms) {
  int fds[2];
  if (pipe(fds) != 0) return {};
  const pid_t pid = fork();
  if (pid == 0) {
    dup2(fds[1], STDOUT_FILENO);
    close(fds[0]);
    close(fds[1]);
    const std::string first_s = std::to_string(first);
    execl(SGLC_CRASH_WRITER, SGLC_CRASH_WRITER, db.c_str(), "robot", first_s.c_str(), "100000", nullptr);
    _exit(127);
  }
  close(fds[1]);
  std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  std::string out;
  char buf[4096];
  ssize_t n;
  while ((n = read(fds[0], buf, sizeof(buf))) > 0) out.append(buf, static_cast<std::size_t>(n));
  close(fds[0]);
  // Only complete lines are acknowledgements; a torn last line was never fully written.
  std::vector<std::pair<std::int64_t, long>> acked;
  std::istringstream lines(out.substr(0, out.rfind('\n') + 1));
  std::int64_t id;
  long seq;
  while (lines >> id >> seq) acked.emplace_back(id, seq);
  return acked;
}

TEST(Durability, SurvivesSigkillAtRandomMoments) {
  TempDir dir;
  const auto db = dir.file("crash.db");
  std::mt19937 rng(2024);
  std::map<std::int64_t, long> acked;
  long next_seq = 0;
  int kills_with_progress = 0;
  for (int round = 0; round < 24; ++round) {
    const int delay = 60 + static_cast<int>(rng() % 200);
    const auto got = runAndKill(db, next_seq, delay);
    for (const auto& [id, seq] : got) {
      acked[id] = seq;
      next_seq = std::max(next_seq, seq + 1);
    }
    kills_with_progress += !got.empty();
    // Reopen after every kill: the file must be whole and hold every acknowledged scan.
    auto store = MapStore::open(options(db));
    ASSERT_EQ(store->integrityCheck(), "ok") << "round " << round;
    const auto st = store->stats("m");
    EXPECT_EQ(st.index_entries, st.scans) << "round " << round;
    for (const auto& [id, seq] : acked) {
      const auto info = store->scanInfo(id);
      ASSERT_TRUE(info) << "acknowledged scan " << id << " lost in round " << round;
      EXPECT_EQ(info->seq, seq);
    }
    // No partial scan: every stored scan has a readable fingerprint. Unacknowledged but committed scans (killed
    // between commit and print) are allowed; they must be complete too.
    EXPECT_GE(st.scans, static_cast<std::int64_t>(acked.size()));
    for (long seq = 0; seq < next_seq + 2; ++seq) {
      const auto id = store->findScan("m", "robot", "run", seq);
      if (!id) continue;
      const auto fp = store->fingerprint(*id);
      ASSERT_NE(fp, nullptr);
      EXPECT_EQ(serialize(*fp), serialize(randomFingerprint(static_cast<std::uint64_t>(seq) * 31 + 7, 20)));
      next_seq = std::max(next_seq, seq + 1);
    }
  }
  EXPECT_GE(kills_with_progress, 20) << "the writer should make progress before most kills";
  EXPECT_GT(acked.size(), 20u);
}

TEST(Durability, ConcurrentWritersAndReadersAgree) {
  TempDir dir;
  auto store = MapStore::open(options(dir.file("map.db")));
  store->createMap("m", DescriptorLayout{}.scanDim());
  constexpr int kWriters = 3, kPerWriter = 40, kReaders = 4;
  std::atomic<int> written{0}, errors{0}, reads{0};
  std::atomic<bool> done{false};
  std::vector<std::thread> threads;
  for (int w = 0; w < kWriters; ++w)
    threads.emplace_back([&, w] {
      try {
        for (int i = 0; i < kPerWriter; ++i) {
          const auto fp = randomFingerprint(static_cast<std::uint64_t>(w) * 100000 + i, 10);
          NewScan ns{.map = "m", .robot = "w" + std::to_string(w), .session = "s", .seq = i, .fingerprint = &fp};
          store->addScan(ns);
          ++written;
        }
      } catch (...) {
        ++errors;
      }
    });
  for (int r = 0; r < kReaders; ++r)
    threads.emplace_back([&, r] {
      std::mt19937 rng(r);
      try {
        while (!done) {
          const int w = static_cast<int>(rng() % kWriters), i = static_cast<int>(rng() % kPerWriter);
          const auto want = randomFingerprint(static_cast<std::uint64_t>(w) * 100000 + i, 10);
          SearchRequest req{.map = "m", .descriptor = want.descriptor, .k = 3};
          const auto hits = store->search(req);
          // Whatever the index returns is complete in the database, and its fingerprint is intact.
          for (const auto& h : hits) {
            const auto fp = store->fingerprint(h.scan_id);
            if (!fp || !store->scanInfo(h.scan_id)) ++errors;
          }
          if (!hits.empty() && hits[0].distance < 1e-6f) {
            const auto fp = store->fingerprint(hits[0].scan_id);
            if (!fp || serialize(*fp) != serialize(want)) ++errors;  // a torn or mixed-up read
          }
          const auto st = store->stats("m");
          if (st.scans != st.index_entries && st.scans > st.index_entries + 0) ++errors;
          ++reads;
        }
      } catch (...) {
        ++errors;
      }
    });
  for (int w = 0; w < kWriters; ++w) threads[w].join();
  done = true;
  for (std::size_t t = kWriters; t < threads.size(); ++t) threads[t].join();
  EXPECT_EQ(errors.load(), 0);
  EXPECT_EQ(written.load(), kWriters * kPerWriter);
  EXPECT_GT(reads.load(), 0);
  const auto st = store->stats("m");
  EXPECT_EQ(st.scans, kWriters * kPerWriter);
  EXPECT_EQ(st.index_entries, kWriters * kPerWriter);
  EXPECT_EQ(st.robots, kWriters);
}

}  // namespace
}  // namespace sglc::storage
