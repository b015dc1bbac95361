// What the parts of the PostgreSQL map store share: the connections, the catalogue with the descriptor
// indexes (a cache of the database, as in the SQLite store), the fingerprint cache, and the change journal that
// keeps several processes' caches in step.
//
// Any number of server processes (replicas) may open one database. Every write takes one database-wide
// advisory lock for its transaction, so writes commit in the order of their ids (scans, loops and journal
// entries alike): a reader that has seen id n has seen every committed id below it. Each write appends an entry
// to the journal (sglc_changes) and notifies; a process applies other processes' entries to its catalogue and
// indexes when notified (or polled), and before each of its own writes, under the lock.
//
// A process that stops inside a write (SIGSTOP, a paused container, a VM stall: its connection stays up) would
// hold the lock, and so stop every process's writes, for as long as it is stopped. The write transaction
// therefore sets its own idle_in_transaction_session_timeout (StoreOptions::stall_timeout_ms): the process
// does only in-memory work between a write's statements, so a transaction idle that long belongs to a stopped
// process, and the server ends its session, which frees the lock. When the process resumes, its next statement
// fails with kUnavailable (nothing of the write was committed, nothing applied to the catalogue, which changes
// only after COMMIT), the caller retries (ingest is idempotent) and the next write reconnects.
#pragma once

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <set>
#include <string>
#include <thread>

#include "catalogue.hpp"
#include "fair_shared_mutex.hpp"
#include "fingerprint_cache.hpp"
#include "postgres.hpp"

namespace sglc::storage::pg {

// Advisory lock keys: (kLockSpace, kWriteLock) orders every write; (kLockSpace, kSchemaLock) the migrations.
constexpr std::int32_t kLockSpace = 0x53474C43;  // "SGLC"
constexpr std::int32_t kSchemaLock = 0, kWriteLock = 1;

// Journal entry kinds (sglc_changes.kind); map_id names the map, ref the row.
enum class Change : std::int16_t {
  kMapCreated = 1,
  kMapDeleted = 2,
  kScanAdded = 3,
  kSessionDeleted = 4,
  kRobotDeleted = 5,
  kScanRetired = 6  // ref: the scan (lifelong maps)
};

struct Core {
  explicit Core(const StoreOptions& options);

  const StoreOptions options;
  const std::string url;  // redacted, for messages
  Conn writer;            // under write_mutex
  Pool readers;
  mutable std::mutex write_mutex;
  mutable FairSharedMutex state_mutex;  // catalogue + indexes + applied
  Catalogue catalogue;
  mutable FingerprintCache cache;
  std::int64_t applied = 0;  // the last journal entry the catalogue and indexes reflect

  // The id of `map` in the catalogue (kNotFound), under a shared lock of its own.
  std::int64_t mapId(const std::string& map) const;
};

// A write: holds write_mutex and a transaction on the writer that holds the database-wide write lock, and has
// applied every other process's committed change. Commit with commit(); destruction rolls back. The server
// ends the transaction when it sends nothing for stall_timeout_ms (above): every statement then fails with
// kUnavailable.
class WriteTx {
 public:
  explicit WriteTx(Core& core);
  // Appends a journal entry and a notification to this transaction; returns the entry's id.
  std::int64_t journal(Change kind, std::int64_t map_id, std::int64_t ref);
  // One entry per ref of `refs` (a PostgreSQL bigint[] literal, "{1,2}") in one statement, and one notification;
  // returns the last entry's id.
  std::int64_t journalEach(Change kind, std::int64_t map_id, const std::string& refs);
  // Commits, then runs `apply` (the change to the catalogue and indexes) under the exclusive state lock, so no
  // reader sees the one without the other, and records `entry` (0: none) as applied.
  template <typename Apply>
  void commit(std::int64_t entry, Apply apply) {
    std::unique_lock lock(core_.state_mutex);
    tx_.commit();
    apply();
    if (entry > core_.applied) core_.applied = entry;
  }
  const Conn& conn() const { return core_.writer; }

 private:
  Core& core_;
  std::lock_guard<std::mutex> write_;
  Transaction tx_;
};

namespace journal {
// Reads the whole catalogue and every map's index in one snapshot, with the journal position it matches.
void load(Core& core);
// Applies the journal's entries after core.applied (the caller holds write_mutex).
void catchUp(Core& core);
}  // namespace journal

// Follows other processes' writes: LISTENs for the journal's notifications and catches up on each, and at
// least every poll_ms in case a notification was missed (a dropped connection).
class Follower {
 public:
  Follower(Core& core, int poll_ms);
  ~Follower();
  Follower(const Follower&) = delete;
  Follower& operator=(const Follower&) = delete;

 private:
  void run();
  Core& core_;
  const int poll_ms_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// The pose graphs this process solves: a session-level advisory lock per map on a connection of its own, so
// that a process that dies (or loses its connection) frees its maps for another to take over. So does a
// process that stops (frozen): the connection has idle_session_timeout = stall_timeout_ms, and a thread of
// this process sends a statement every third of it while the process runs.
class GraphOwner {
 public:
  GraphOwner(std::string url, int stall_timeout_ms);
  ~GraphOwner();
  GraphOwner(const GraphOwner&) = delete;
  GraphOwner& operator=(const GraphOwner&) = delete;
  // Whether this process holds map_id's lock (checked live: a lost connection loses every lock), taking it
  // when free (MapStore::GraphClaim).
  MapStore::GraphClaim claim(std::int64_t map_id);

 private:
  void keepAlive();
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  const std::string url_;
  const int stall_ms_;
  std::unique_ptr<Conn> conn_;
  std::set<std::int64_t> held_;
  std::thread keeper_;
};

}  // namespace sglc::storage::pg
