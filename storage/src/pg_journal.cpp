// The change journal: loading the catalogue and indexes from one snapshot, applying other processes' writes
// in journal order, the write transaction that keeps that order, and the thread that follows notifications.
#include <poll.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <map>
#include <unordered_set>

#include "map_index.hpp"
#include "pg_core.hpp"

namespace sglc::storage::pg {
namespace {

using Code = StorageError::Code;

constexpr const char* kChannel = "sglc_changes";
constexpr std::int64_t kBatch = 20000;

MapState newMap(const Core& core, std::int64_t id, std::string name, std::int64_t dim) {
  if (dim < 1 || dim > kMaxDescriptorDim)
    throw StorageError(Code::kCorrupt, "map '" + name + "' has descriptor dimension " + std::to_string(dim) + " (1.." +
                                           std::to_string(kMaxDescriptorDim) + " expected)");
  MapState m;
  m.id = id;
  m.name = std::move(name);
  m.dim = static_cast<int>(dim);
  m.index = std::make_unique<DescriptorIndex>(m.dim, core.options.index);
  return m;
}

// Columns: id, robot_id, session_id, seq, stamp, descriptor starting at `col`.
IndexEntry entryOf(const Result& r, int row, int col, const MapState& m) {
  const auto blob = r.blob(row, col + 5);
  if (blob.size() != static_cast<std::size_t>(m.dim) * sizeof(float))
    throw StorageError(Code::kCorrupt, "scan " + std::to_string(r.i64(row, col)) + " of map '" + m.name +
                                           "' has a descriptor of the wrong length");
  return {r.i64(row, col), r.i64(row, col + 1), r.i64(row, col + 2), r.i64(row, col + 3),
          r.isNull(row, col + 4) ? std::nan("") : r.f64(row, col + 4)};
}

void loadScans(const Core& core, MapState& m) {
  std::vector<IndexEntry> entries;
  std::vector<float> vectors;
  for (std::int64_t after = 0;;) {
    const auto r = core.writer.query(
        "SELECT id, robot_id, session_id, seq, stamp, descriptor FROM scans WHERE map_id = $1 AND id > $2"
        " ORDER BY id LIMIT $3",
        {m.id, after, kBatch});
    for (int i = 0; i < r.rows(); ++i) {
      entries.push_back(entryOf(r, i, 0, m));
      const auto* f = reinterpret_cast<const float*>(r.blob(i, 5).data());
      vectors.insert(vectors.end(), f, f + m.dim);
    }
    if (r.rows() < kBatch) break;
    after = entries.back().scan_id;
  }
  m.index->build(std::move(entries), vectors);
}

MapState* mapById(Core& core, std::int64_t id) {
  const auto name = core.catalogue.nameOf(id);
  return name.empty() ? nullptr : &core.catalogue.map(name);
}

// Drops the scans `keep` selects from m's index and the fingerprint cache.
template <typename Pred>
void dropScans(Core& core, MapState& m, Pred keep) {
  const auto ids = m.index->liveIds(keep);
  m.index->remove(ids);
  for (const auto id : ids) core.cache.erase(id);
}

// Columns of catchUp's query: 0 id, 1 kind, 2 map_id, 3 ref, 4 map name, 5 dim, 6 robot name, 7 session name,
// 8.. scan (id, robot_id, session_id, seq, stamp, descriptor).
void apply(Core& core, const Result& r, int i) {
  const auto kind = static_cast<Change>(r.i64(i, 1));
  const auto map_id = r.i64(i, 2), ref = r.i64(i, 3);
  if (kind == Change::kMapCreated) {
    if (!r.isNull(i, 4) && core.catalogue.nameOf(map_id).empty())
      core.catalogue.add(newMap(core, map_id, r.text(i, 4), r.i64(i, 5)));
    return;
  }
  MapState* m = mapById(core, map_id);
  if (!m) return;  // deleted since
  switch (kind) {
    case Change::kMapDeleted:
      dropScans(core, *m, [](const IndexEntry&) { return true; });
      core.catalogue.remove(m->name);
      break;
    case Change::kScanAdded: {
      if (r.isNull(i, 8)) break;  // deleted since: its deletion follows in the journal
      const auto e = entryOf(r, i, 8, *m);
      m->robots[r.text(i, 6)] = e.robot_id;
      m->sessions[{e.robot_id, r.text(i, 7)}] = e.session_id;
      m->index->add(e, reinterpret_cast<const float*>(r.blob(i, 13).data()));
      break;
    }
    case Change::kSessionDeleted:
      m->deletions += 1;
      dropScans(core, *m, [&](const IndexEntry& e) { return e.session_id == ref; });
      std::erase_if(m->sessions, [&](const auto& s) { return s.second == ref; });
      break;
    case Change::kRobotDeleted:
      m->deletions += 1;
      dropScans(core, *m, [&](const IndexEntry& e) { return e.robot_id == ref; });
      std::erase_if(m->sessions, [&](const auto& s) { return s.first.first == ref; });
      std::erase_if(m->robots, [&](const auto& r) { return r.second == ref; });
      break;
    case Change::kScanRetired:  // gathered by catchUp and applied a map at a time
      break;
    default:
      break;
  }
}

}  // namespace

std::int64_t Core::mapId(const std::string& map) const {
  std::shared_lock lock(state_mutex);
  return catalogue.map(map).id;
}

namespace journal {

void load(Core& core) {
  const Conn& db = core.writer;
  Transaction tx(db);
  db.exec("SET TRANSACTION ISOLATION LEVEL REPEATABLE READ READ ONLY");  // one snapshot for all that follows
  core.applied = db.query("SELECT coalesce(max(id), 0) FROM sglc_changes").i64(0, 0);
  {
    const auto r = db.query("SELECT id, name, descriptor_dim FROM maps ORDER BY id");
    for (int i = 0; i < r.rows(); ++i) core.catalogue.add(newMap(core, r.i64(i, 0), r.text(i, 1), r.i64(i, 2)));
  }
  {
    const auto r = db.query("SELECT id, map_id, name FROM robots");
    for (int i = 0; i < r.rows(); ++i)
      if (auto* m = mapById(core, r.i64(i, 1))) m->robots[r.text(i, 2)] = r.i64(i, 0);
  }
  {
    const auto r =
        db.query("SELECT x.id, x.robot_id, x.name, r.map_id FROM sessions x JOIN robots r ON r.id = x.robot_id");
    for (int i = 0; i < r.rows(); ++i)
      if (auto* m = mapById(core, r.i64(i, 3))) m->sessions[{r.i64(i, 1), r.text(i, 2)}] = r.i64(i, 0);
  }
  for (auto& [name, m] : core.catalogue.maps()) loadScans(core, m);
  tx.commit();
}

void catchUp(Core& core) {
  for (;;) {
    const auto r = core.writer.query(
        "SELECT c.id, c.kind, c.map_id, c.ref, m.name, m.descriptor_dim, rb.name, x.name,"
        " s.id, s.robot_id, s.session_id, s.seq, s.stamp, s.descriptor"
        " FROM sglc_changes c LEFT JOIN maps m ON c.kind = 1 AND m.id = c.map_id"
        " LEFT JOIN scans s ON c.kind = 3 AND s.id = c.ref LEFT JOIN robots rb ON rb.id = s.robot_id"
        " LEFT JOIN sessions x ON x.id = s.session_id WHERE c.id > $1 ORDER BY c.id LIMIT $2",
        {core.applied, kBatch});
    if (r.rows() == 0) return;
    std::unique_lock lock(core.state_mutex);
    // Retired scans leave each index in one pass (a pass per scan would cost retired x index entries under the
    // exclusive lock), before any other kind of entry that follows them is applied.
    std::map<std::int64_t, std::unordered_set<std::int64_t>> retired;
    const auto flush = [&] {
      for (auto& [map_id, ids] : retired)
        if (MapState* m = mapById(core, map_id)) {
          m->index->remove(ids);
          m->deletions += 1;
          for (const auto id : ids) core.cache.erase(id);
        }
      retired.clear();
    };
    for (int i = 0; i < r.rows(); ++i) {
      if (static_cast<Change>(r.i64(i, 1)) == Change::kScanRetired) {
        retired[r.i64(i, 2)].insert(r.i64(i, 3));
      } else {
        flush();
        apply(core, r, i);
      }
      core.applied = r.i64(i, 0);
    }
    flush();
    if (r.rows() < kBatch) return;
  }
}

}  // namespace journal

// The writer, reconnected first if the server dropped it (a restart): the transaction then begins on it.
const Conn& reconnected(Core& core) {
  core.writer.ensureOpen();
  return core.writer;
}

WriteTx::WriteTx(Core& core) : core_(core), write_(core.write_mutex), tx_(reconnected(core)) {
  // The transaction's own idle limit (set_config(..., true) is SET LOCAL), in the statement that takes the lock:
  // from here on, a process that stops between statements (frozen) holds the lock at most stall_timeout_ms
  // before the server ends its session. The process does only in-memory work between a write's statements.
  core_.writer.query(
      "SELECT set_config('idle_in_transaction_session_timeout', $3, true), pg_advisory_xact_lock($1, $2)",
      {kLockSpace, kWriteLock, std::to_string(std::max(0, core_.options.stall_timeout_ms))});
  journal::catchUp(core_);
}

std::int64_t WriteTx::journal(Change kind, std::int64_t map_id, std::int64_t ref) {
  const auto r = core_.writer.query("INSERT INTO sglc_changes(map_id, kind, ref) VALUES($1, $2, $3) RETURNING id",
                                    {map_id, static_cast<int>(kind), ref});
  const auto id = r.i64(0, 0);
  core_.writer.query("SELECT pg_notify($1, $2)", {kChannel, std::to_string(id)});  // the entry, for followers
  return id;
}

std::int64_t WriteTx::journalEach(Change kind, std::int64_t map_id, const std::string& refs) {
  const auto r = core_.writer.query(
      "WITH e AS (INSERT INTO sglc_changes(map_id, kind, ref) SELECT $1, $2, unnest($3::bigint[]) RETURNING id)"
      " SELECT coalesce(max(id), 0) FROM e",
      {map_id, static_cast<int>(kind), refs});
  const auto id = r.i64(0, 0);
  core_.writer.query("SELECT pg_notify($1, $2)", {kChannel, std::to_string(id)});
  return id;
}

GraphOwner::GraphOwner(std::string url, int stall_timeout_ms) : url_(std::move(url)), stall_ms_(stall_timeout_ms) {
  if (stall_ms_ > 0) keeper_ = std::thread([this] { keepAlive(); });
}

GraphOwner::~GraphOwner() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (keeper_.joinable()) keeper_.join();
}

void GraphOwner::keepAlive() {
  std::unique_lock lock(mutex_);
  while (!stop_) {
    wake_.wait_for(lock, std::chrono::milliseconds(std::max(50, stall_ms_ / 3)));
    if (stop_ || !conn_) continue;
    try {
      conn_->exec("SELECT 1");
    } catch (const StorageError&) {
      // Lost (or ended): the next claim finds out and reconnects.
    }
  }
}

MapStore::GraphClaim GraphOwner::claim(std::int64_t map_id) {
  using Claim = MapStore::GraphClaim;
  // One 64-bit key per map, apart from the store's (int, int) keys: the two kinds never conflict.
  constexpr std::int64_t kGraphKeys = std::int64_t{0x5347} << 48;
  std::lock_guard lock(mutex_);
  try {
    if (conn_) {
      try {
        conn_->exec("SELECT 1");  // alive? A dropped connection has lost its locks, perhaps to another process.
      } catch (const StorageError&) {
        held_.clear();
        conn_.reset();
      }
    }
    if (!conn_)
      conn_ = std::make_unique<Conn>(
          url_, stall_ms_ > 0 ? "SET idle_session_timeout = " + std::to_string(stall_ms_) : std::string());
    if (held_.count(map_id)) return Claim::kHeld;
    if (!conn_->query("SELECT pg_try_advisory_lock($1)", {kGraphKeys + map_id}).boolean(0, 0)) return Claim::kElsewhere;
    held_.insert(map_id);
    return Claim::kTaken;
  } catch (const StorageError&) {
    return Claim::kElsewhere;
  }
}

Follower::Follower(Core& core, int poll_ms) : core_(core), poll_ms_(poll_ms), thread_([this] { run(); }) {}

Follower::~Follower() {
  stop_ = true;
  thread_.join();
}

void Follower::run() {
  std::unique_ptr<Conn> listener;
  while (!stop_) {
    try {
      // LISTEN is part of the connection's setup: a reconnect listens again.
      if (!listener || !listener->ensureOpen())
        listener = std::make_unique<Conn>(core_.options.path, std::string("LISTEN ") + kChannel);
      // Wait for a notification in slices short enough to notice stop_ soon.
      pollfd pfd{PQsocket(listener->get()), POLLIN, 0};
      // A notification names its journal entry: this process's own writes, already applied, need no catch-up.
      std::int64_t newest = 0;
      bool notified = false;
      for (int waited = 0; waited < poll_ms_ && !stop_ && !notified; waited += 100) {
        if (::poll(&pfd, 1, 100) > 0) {
          PQconsumeInput(listener->get());
          while (PGnotify* n = PQnotifies(listener->get())) {
            newest = std::max(newest, static_cast<std::int64_t>(std::strtoll(n->extra, nullptr, 10)));
            PQfreemem(n);
          }
          if (newest > 0) {
            std::shared_lock lock(core_.state_mutex);
            notified = newest > core_.applied;
          }
          if (PQstatus(listener->get()) != CONNECTION_OK) break;
        }
      }
      if (stop_) break;
      std::lock_guard write(core_.write_mutex);
      if (core_.writer.ensureOpen()) journal::catchUp(core_);
    } catch (const std::exception&) {
      // The database is unreachable (or a damaged row): try again after a pause; the next write reports it to its
      // caller.
      listener.reset();
      for (int i = 0; i < poll_ms_ / 100 + 1 && !stop_; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
}

}  // namespace sglc::storage::pg
