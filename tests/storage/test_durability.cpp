// Crash safety and concurrency of the map store.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <map>
#include <optional>
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

// The crash writer's stdout: "ready" once its map exists (before any scan), then "<id> <seq>" for each
// acknowledged scan. Read as it arrives so that the kill can be placed after readiness (and after a number
// of acknowledgements) instead of after a wall-clock delay from fork, which a loaded machine stretches.
class WriterOutput {
 public:
  explicit WriterOutput(int fd) : fd_(fd) {}

  // Reads until done() holds (true), the deadline passes or the writer closes its stdout (false).
  template <typename Done>
  bool readUntil(std::chrono::steady_clock::time_point deadline, Done&& done) {
    while (!done()) {
      if (eof_) return false;
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return false;
      pollfd p{fd_, POLLIN, 0};
      const int r = poll(&p, 1, static_cast<int>(std::min<std::int64_t>(left.count(), 1000)));
      if (r < 0 && errno != EINTR) return false;
      if (r > 0) readSome();
    }
    return true;
  }
  // Keeps the pipe drained for `ms` milliseconds.
  void readFor(int ms) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    readUntil(until, [] { return false; });
  }
  // Everything left, once the writer is dead.
  void readToEof() {
    while (!eof_) readSome();
  }

  bool ready() const { return ready_; }
  // Only complete lines count: a torn last line was never fully written, so it acknowledges nothing.
  const std::vector<std::pair<std::int64_t, long>>& acked() const { return acked_; }
  const std::vector<std::string>& badLines() const { return bad_lines_; }
  const std::string& text() const { return text_; }

 private:
  void readSome() {
    char buf[4096];
    const ssize_t n = read(fd_, buf, sizeof(buf));
    if (n == 0 || (n < 0 && errno != EINTR && errno != EAGAIN)) {
      eof_ = true;
      return;
    }
    if (n < 0) return;
    text_.append(buf, static_cast<std::size_t>(n));
    std::size_t nl;
    while ((nl = text_.find('\n', parsed_)) != std::string::npos) {
      parseLine(text_.substr(parsed_, nl - parsed_));
      parsed_ = nl + 1;
    }
  }
  void parseLine(const std::string& line) {
    if (line == kReadyLine) {
      if (ready_ || !acked_.empty()) bad_lines_.push_back(line + " (out of order)");
      ready_ = true;
      return;
    }
    std::istringstream ss(line);
    std::int64_t id;
    long seq;
    std::string rest;
    if (!ready_ || !(ss >> id >> seq) || (ss >> rest)) {
      bad_lines_.push_back(line);
      return;
    }
    acked_.emplace_back(id, seq);
  }

  static constexpr const char* kReadyLine = "ready";
  int fd_;
  bool eof_ = false;
  bool ready_ = false;
  std::string text_;
  std::size_t parsed_ = 0;
  std::vector<std::pair<std::int64_t, long>> acked_;
  std::vector<std::string> bad_lines_;
};

// Generous: a sanitizer build on a loaded machine can take seconds to open the store; only a hung writer
// takes this long.
constexpr auto kWriterBound = std::chrono::seconds(120);

// Runs the writer from seq `first`; once it is ready (its map exists) and has acknowledged `min_acks` scans,
// lets it run `delay_ms` more and kills it with SIGKILL. Returns what it acknowledged, or nullopt (and a test
// failure saying why) when it never got there.
std::optional<std::vector<std::pair<std::int64_t, long>>> runAndKill(const std::string& db, long first, int min_acks,
                                                                     int delay_ms) {
  int fds[2];
  if (pipe(fds) != 0) {
    ADD_FAILURE() << "pipe: " << std::strerror(errno);
    return std::nullopt;
  }
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
  if (pid < 0) {
    close(fds[0]);
    ADD_FAILURE() << "fork: " << std::strerror(errno);
    return std::nullopt;
  }
  WriterOutput out(fds[0]);
  const auto deadline = std::chrono::steady_clock::now() + kWriterBound;
  const bool ready = out.readUntil(deadline, [&] { return out.ready(); });
  const bool progressed =
      ready && out.readUntil(deadline, [&] { return out.acked().size() >= static_cast<std::size_t>(min_acks); });
  if (progressed) out.readFor(delay_ms);
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  out.readToEof();
  close(fds[0]);
  const bool killed = WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL;
  if (!ready || !progressed || !killed || !out.badLines().empty()) {
    const std::string bound = " within " + std::to_string(kWriterBound.count()) + " s";
    std::string what;
    if (!ready)
      what = "did not report ready" + bound;
    else if (!progressed)
      what =
          "acknowledged " + std::to_string(out.acked().size()) + " of " + std::to_string(min_acks) + " scans" + bound;
    else if (!killed)
      what = "exited before it was killed";
    else
      what = "printed unexpected lines (first: '" + out.badLines().front() + "')";
    ADD_FAILURE() << "crash writer (first seq " << first << ") " << what << "; wait status " << status << "; output:\n"
                  << out.text().substr(0, 2000);
    return std::nullopt;
  }
  return out.acked();
}

TEST(Durability, SurvivesSigkillAtRandomMoments) {
  TempDir dir;
  const auto db = dir.file("crash.db");
  std::mt19937 rng(2024);
  std::map<std::int64_t, long> acked;
  long next_seq = 0;
  int kills_with_progress = 0, rounds_waiting_for_acks = 0;
  std::size_t min_total_acks = 0;
  for (int round = 0; round < 24; ++round) {
    // Every fourth round is killed at a random moment after the writer is ready, possibly before its first
    // scan is acknowledged (or stored); the others after 1..4 acknowledgements; then a random 0-99 ms. Which
    // moment is random, but no round depends on how fast the writer starts or writes.
    const int min_acks = round % 4 == 0 ? 0 : 1 + static_cast<int>(rng() % 4);
    const int delay = static_cast<int>(rng() % 100);
    rounds_waiting_for_acks += min_acks > 0;
    min_total_acks += static_cast<std::size_t>(min_acks);
    const auto got = runAndKill(db, next_seq, min_acks, delay);
    ASSERT_TRUE(got) << "round " << round << ": the crash writer failed (see above)";
    for (const auto& [id, seq] : *got) {
      acked[id] = seq;
      next_seq = std::max(next_seq, seq + 1);
    }
    kills_with_progress += !got->empty();
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
  RecordProperty("acknowledged_scans", static_cast<int>(acked.size()));
  RecordProperty("scans_checked", static_cast<int>(next_seq));
  EXPECT_GE(kills_with_progress, rounds_waiting_for_acks);
  EXPECT_GE(acked.size(), min_total_acks);
  EXPECT_GT(min_total_acks, 20u) << "the kill plan should let the writer store a fair number of scans";
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
