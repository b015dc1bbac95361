// A replica that stalls inside a write transaction (its process frozen: SIGSTOP, a paused container, a VM stall;
// its TCP connection stays up) holds the database-wide write lock only until the server ends its idle
// transaction (StoreOptions::stall_timeout_ms): the other replicas write again, the stalled one finds its
// transaction gone when it resumes (kUnavailable: worth a retry, nothing of it stored) and its next write
// reconnects. The stall is simulated in-process: a write transaction on a store's core that sends nothing.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <thread>

#include "backend.hpp"
#include "pg_core.hpp"

namespace sglc::storage {
namespace {

using testing::Backend;
using testing::errorCode;
using testing::randomFingerprint;
using Clock = std::chrono::steady_clock;

class PgStalledWriter : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!backend_.unavailable().empty()) GTEST_SKIP() << backend_.unavailable();
  }
  std::int64_t count(const std::string& sql) { return pg::Conn(backend_.options().path).query(sql.c_str()).i64(0, 0); }
  Backend backend_{"postgresql"};
};

TEST_F(PgStalledWriter, LosesTheWriteLockWithinItsStallTimeoutAndRecovers) {
  auto o = backend_.options();
  o.stall_timeout_ms = 500;
  o.busy_timeout_ms = 30000;  // the other replica waits for the lock instead of giving up (the bug: for ever)
  auto other = MapStore::open(o);
  const auto fp = randomFingerprint(5);
  const auto map_id = other->createMap("m", static_cast<int>(fp.descriptor.size())).id;

  pg::Core stalled(o);
  pg::journal::load(stalled);
  std::optional<pg::WriteTx> tx(std::in_place, stalled);
  tx->conn().query("INSERT INTO robots(map_id, name) VALUES($1, 'stalled')", {map_id});
  // ... and sends nothing more: the other replica's write waits for the lock until the server ends the stall.
  const auto t0 = Clock::now();
  const auto id = other->addScan({.map = "m", .robot = "r", .session = "s", .seq = 0, .fingerprint = &fp});
  const auto waited = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_LT(waited, 10.0) << "the other replica waited for the stalled one's lock";
  EXPECT_GE(waited, 0.3) << "the other replica did not wait for the lock at all";

  // Resumed: its transaction is gone, with everything it wrote, and the caller is told to retry.
  EXPECT_EQ(errorCode([&] { tx->journal(pg::Change::kScanAdded, map_id, id); }), StorageError::Code::kUnavailable);
  tx.reset();
  EXPECT_EQ(count("SELECT count(*) FROM robots WHERE name = 'stalled'"), 0);
  EXPECT_EQ(count("SELECT count(*) FROM sglc_changes WHERE kind = 3"), 1);  // the other replica's scan only

  // Its next write reconnects (with the writer's settings) and commits; the catalogue catches up first.
  {
    pg::WriteTx again(stalled);
    EXPECT_EQ(again.conn().query("SHOW lock_timeout").text(0, 0), "30s");
    again.commit(0, [] {});
  }
  EXPECT_EQ(stalled.catalogue.map("m").index->live(), 1);
  EXPECT_EQ(count("SELECT count(*) FROM scans"), 1);
}

// A write transaction that keeps working is not ended, however long it takes in all: only idling counts.
TEST_F(PgStalledWriter, AWriterThatKeepsSendingKeepsItsTransaction) {
  auto o = backend_.options();
  o.stall_timeout_ms = 1000;
  auto store = MapStore::open(o);
  pg::Core core(o);
  pg::journal::load(core);
  pg::WriteTx tx(core);
  for (int i = 0; i < 15; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    tx.conn().query("SELECT pg_sleep(0.05)");
  }
  EXPECT_NO_THROW(tx.commit(0, [] {}));
}

// A map's pose-graph lock lives on a session with idle_session_timeout = stall_timeout_ms (a frozen holder loses
// it): while the process runs, its keep-alive holds the session open, so the lock stays put however long the
// holder goes without claiming.
TEST_F(PgStalledWriter, AGraphHolderThatRunsKeepsItsMapsPastTheStallTimeout) {
  using Claim = MapStore::GraphClaim;
  auto o = backend_.options();
  o.stall_timeout_ms = 300;
  auto a = MapStore::open(o);
  auto b = MapStore::open(o);
  const auto id = a->createMap("m", 8).id;
  EXPECT_EQ(a->claimGraph(id), Claim::kTaken);
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_EQ(b->claimGraph(id), Claim::kElsewhere);
  EXPECT_EQ(a->claimGraph(id), Claim::kHeld);  // not lost and taken again
}

// ... and a holder whose process is frozen (SIGSTOP: its connection stays up) loses them within about the
// timeout: another process takes the map over.
TEST_F(PgStalledWriter, AFrozenGraphHolderLosesItsMaps) {
  using Claim = MapStore::GraphClaim;
  auto o = backend_.options();
  o.stall_timeout_ms = 500;
  const auto id = MapStore::open(o)->createMap("m", 8).id;
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();  // no thread runs here yet: the child opens its own store
  ASSERT_GE(child, 0);
  if (child == 0) {
    auto holder = MapStore::open(o);
    const char ok = holder->claimGraph(id) == Claim::kTaken ? 'y' : 'n';
    if (::write(ready[1], &ok, 1) != 1) ::_exit(1);
    for (;;) ::pause();
  }
  char ok = 0;
  ASSERT_EQ(::read(ready[0], &ok, 1), 1);
  ASSERT_EQ(ok, 'y');
  auto other = MapStore::open(o);
  EXPECT_EQ(other->claimGraph(id), Claim::kElsewhere);
  ::kill(child, SIGSTOP);
  const auto t0 = Clock::now();
  bool taken = false;
  while (!taken && Clock::now() - t0 < std::chrono::seconds(30)) {
    taken = other->claimGraph(id) == Claim::kTaken;
    if (!taken) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  const auto waited = std::chrono::duration<double>(Clock::now() - t0).count();
  ::kill(child, SIGKILL);
  ::waitpid(child, nullptr, 0);
  EXPECT_TRUE(taken) << "a frozen holder kept the map's pose graph for 30 s";
  EXPECT_LT(waited, 10.0);
}

}  // namespace
}  // namespace sglc::storage
