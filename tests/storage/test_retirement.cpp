// Lifelong maps: a retirement killed with SIGKILL at random moments leaves the map as it was before or as it
// is after, never in between: no scan half gone, no loop to a scan that left, no place of a missing scan, and
// the index agreeing with the database.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <random>
#include <set>
#include <string>

#include "storage_test_util.hpp"

#ifndef SGLC_CRASH_WRITER
#error "SGLC_CRASH_WRITER must name the crash writer executable"
#endif

namespace sglc::storage {
namespace {

using testing::options;
using testing::randomFingerprint;
using testing::TempDir;

constexpr int kScans = 400;  // per robot

// Map "m": robots a and b drive `kScans` scans each; b's scans have a loop to a's scan of the same seq, and are
// not versions of their places (a's are).
void prepare(const std::string& db) {
  auto store = MapStore::open(options(db));
  store->createMap("m", DescriptorLayout{}.scanDim());
  std::vector<std::int64_t> a, b;
  std::vector<PlaceRecord> places;
  for (const char* robot : {"a", "b"})
    for (int seq = 0; seq < kScans; ++seq) {
      const auto fp = randomFingerprint(static_cast<std::uint64_t>(seq * 2 + (robot[0] == 'b')), 8);
      const auto id = store->addScan({.map = "m", .robot = robot, .session = "run", .seq = seq, .fingerprint = &fp});
      (robot[0] == 'a' ? a : b).push_back(id);
    }
  for (int seq = 0; seq < kScans; ++seq) {
    store->addLoop("m", {0, b[seq], a[seq], Mat4d::Identity(), 0.5, 0.6, 0.1, 9});
    places.push_back({a[seq], a[seq], true});
    places.push_back({b[seq], a[seq], false});
  }
  store->setPlaces("m", places);
}

// Runs the retiring child, kills it `delay_us` after it said "ready" (it may have finished by then). Returns
// whether it reported "done" before it died.
bool retireAndKill(const std::string& db, int delay_us) {
  int fds[2];
  if (pipe(fds) != 0) {
    ADD_FAILURE() << "pipe: " << std::strerror(errno);
    return false;
  }
  const pid_t pid = fork();
  if (pid == 0) {
    dup2(fds[1], STDOUT_FILENO);
    close(fds[0]);
    close(fds[1]);
    execl(SGLC_CRASH_WRITER, SGLC_CRASH_WRITER, db.c_str(), "retire", nullptr);
    _exit(127);
  }
  close(fds[1]);
  std::string text;
  char buf[256];
  // Block until "ready" (or the child's end): no wall-clock bound decides the outcome.
  while (text.find("ready\n") == std::string::npos) {
    const ssize_t n = read(fds[0], buf, sizeof(buf));
    if (n <= 0) break;
    text.append(buf, static_cast<std::size_t>(n));
  }
  EXPECT_NE(text.find("ready\n"), std::string::npos) << "the retiring child never got ready: " << text;
  usleep(static_cast<useconds_t>(delay_us));
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  for (ssize_t n; (n = read(fds[0], buf, sizeof(buf))) > 0;) text.append(buf, static_cast<std::size_t>(n));
  close(fds[0]);
  EXPECT_TRUE((WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) || (WIFEXITED(status) && WEXITSTATUS(status) == 0))
      << "status " << status << ": " << text;
  return text.find("done\n") != std::string::npos;
}

TEST(Retirement, SigkillLeavesTheMapBeforeOrAfterNeverBetween) {
  TempDir dir;
  const auto pristine = dir.file("pristine.db");
  prepare(pristine);
  std::mt19937 rng(41);
  int before = 0, after = 0;
  for (int round = 0; round < 12; ++round) {
    const auto db = dir.file("round" + std::to_string(round) + ".db");
    std::filesystem::copy_file(pristine, db);
    for (const char* suffix : {"-wal", "-shm"})
      if (std::filesystem::exists(pristine + suffix)) std::filesystem::copy_file(pristine + suffix, db + suffix);
    // With the index snapshot written when the pristine map was closed: a reopen after the retirement committed
    // must not load it (the map's generation moved on), one after a kill before the commit may.
    ASSERT_TRUE(std::filesystem::exists(pristine + ".index")) << "no index snapshot beside the map";
    std::filesystem::copy(pristine + ".index", db + ".index", std::filesystem::copy_options::recursive);
    // Kills at once, within the first 20 ms (while the transaction runs, on this machine), or within 200 ms.
    const int delay_us = round == 0 ? 0 : static_cast<int>(rng() % (round % 2 ? 20000 : 200000));
    const bool done = retireAndKill(db, delay_us);
    auto store = MapStore::open(options(db));
    ASSERT_EQ(store->integrityCheck(), "ok") << "round " << round;
    const auto st = store->stats("m");
    EXPECT_EQ(st.index_entries, st.scans) << "round " << round;
    const auto loops = store->loops("m");
    const auto places = store->places("m");
    if (st.scans == 2 * kScans) {  // before: nothing of the retirement landed
      EXPECT_FALSE(done) << "round " << round << ": acknowledged, then lost";
      EXPECT_EQ(st.retired_scans, 0);
      EXPECT_EQ(loops.size(), static_cast<std::size_t>(kScans));
      EXPECT_EQ(places.size(), static_cast<std::size_t>(2 * kScans));
      ++before;
    } else {  // after: all of it
      ASSERT_EQ(st.scans, kScans) << "round " << round << ": a retirement half done";
      EXPECT_EQ(st.retired_scans, kScans);
      EXPECT_GT(st.retired_bytes, 0);
      EXPECT_EQ(loops.size(), static_cast<std::size_t>(kScans - 1));  // the moved loops, no loop to b
      EXPECT_EQ(places.size(), static_cast<std::size_t>(kScans));
      ++after;
    }
    std::set<std::int64_t> ids;
    for (const auto& n : store->graphNodes("m")) ids.insert(n.scan_id);
    for (const auto& l : loops)
      ASSERT_TRUE(ids.count(l.query_scan) && ids.count(l.candidate_scan)) << "round " << round << ": dangling loop";
    for (const auto& p : places) ASSERT_TRUE(ids.count(p.scan_id)) << "round " << round << ": dangling place";
  }
  RecordProperty("killed_before_commit", before);
  RecordProperty("finished_or_committed", after);
}

}  // namespace
}  // namespace sglc::storage
