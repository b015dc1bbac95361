// What only the PostgreSQL map store has: a server to reach, other applications' databases to refuse, and other
// processes (replicas) writing the same map. The behaviour both back-ends share is tested on both in
// test_map_store.cpp.
#include <atomic>
#include <chrono>
#include <future>
#include <set>
#include <thread>

#include "backend.hpp"
#include "older_formats.hpp"
#include "pg_core.hpp"
#include "sglc/background.hpp"
#include "sglc/descriptors.hpp"

namespace sglc::storage {
namespace {

using testing::Backend;
using testing::errorCode;
using testing::randomFingerprint;

class PostgresStore : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!backend_.unavailable().empty()) GTEST_SKIP() << backend_.unavailable();
  }
  // SQL on the test's database behind the store's back.
  void exec(const std::string& sql) { pg::Conn(backend_.options().path).exec(sql); }
  Backend backend_{"postgresql"};
};

// Waits (up to a minute, far beyond any expected lag) until `done` holds; the test asserts the result, so a
// slow machine only makes it slower.
bool eventually(const std::function<bool()>& done) {
  for (int i = 0; i < 6000; ++i) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return done();
}

std::vector<std::int64_t> hits(const MapStore& store, const Fingerprint& fp, int k = 50) {
  std::vector<std::int64_t> out;
  for (const auto& h : store.search({.map = "m", .descriptor = fp.descriptor, .k = k})) out.push_back(h.scan_id);
  return out;
}

// The message (what a gRPC caller is told) names no user, host, port or database; the detail (the operator's
// log) says where, without the password.
TEST_F(PostgresStore, AnUnreachableServerIsUnavailableAndItsAddressStaysInTheLog) {
  auto o = backend_.options();
  o.path = "postgresql://sglcuser:s3cret@127.0.0.1:1/mapdb?connect_timeout=5";
  try {
    MapStore::open(o);
    ADD_FAILURE() << "opened a store on a closed port";
  } catch (const StorageError& e) {
    EXPECT_EQ(e.code(), StorageError::Code::kUnavailable);
    const std::string message = e.what();
    EXPECT_EQ(message, "the map database (PostgreSQL) cannot be reached");
    for (const char* secret : {"s3cret", "sglcuser", "127.0.0.1", "mapdb"})
      EXPECT_EQ(message.find(secret), std::string::npos) << secret << " in " << message;
    EXPECT_NE(e.detail().find("postgresql://sglcuser:***@127.0.0.1:1/mapdb"), std::string::npos) << e.detail();
    EXPECT_EQ(e.detail().find("s3cret"), std::string::npos) << e.detail();
  }
  o.path = "postgresql://[::1";  // not a URL libpq can parse
  EXPECT_EQ(errorCode([&] { MapStore::open(o); }), StorageError::Code::kInvalidArgument);
  EXPECT_EQ(pg::redacted("postgresql://u:pw@h/db?password=x&sslmode=require"),
            "postgresql://u:***@h/db?password=***&sslmode=require");
  EXPECT_EQ(pg::redacted("postgres://h/db?pass%77ord=x"), "postgres://h/db?pass%77ord=***");  // libpq decodes names
}

TEST_F(PostgresStore, RefusesAForeignDatabaseAndANewerSchemaWithoutTouchingThem) {
  exec("CREATE TABLE inventory(x integer); INSERT INTO inventory VALUES (7)");
  EXPECT_EQ(errorCode([&] { backend_.open(); }), StorageError::Code::kCorrupt);
  pg::Conn conn(backend_.options().path);
  EXPECT_EQ(conn.query("SELECT count(*) FROM pg_tables WHERE schemaname = 'public'").i64(0, 0), 1);
  exec("DROP TABLE inventory");
  { backend_.open()->createMap("m", 8); }
  exec("UPDATE sglc_meta SET value = '99' WHERE key = 'schema_version'");
  try {
    backend_.open();
    ADD_FAILURE() << "opened a newer schema";
  } catch (const StorageError& e) {
    EXPECT_EQ(e.code(), StorageError::Code::kNewerSchema);
    EXPECT_NE(std::string(e.what()).find("newer"), std::string::npos) << e.what();
  }
  EXPECT_EQ(conn.query("SELECT count(*) FROM maps").i64(0, 0), 1);
}

// Schema 1 -> 2: the scans of older fingerprint formats get the current descriptor in their indexed column,
// in batches; a blob that does not load keeps its row as it was (it is corrupt when read, not lost).
TEST_F(PostgresStore, MigratesOlderFingerprintsToTheCurrentDescriptor) {
  std::vector<std::int64_t> ids;
  std::vector<Fingerprint> fps;
  const auto dim = static_cast<int>(randomFingerprint(1).descriptor.size());
  {
    auto store = backend_.open();
    store->createMap("m", dim);
    for (int k = 0; k < 300; ++k) {  // more than one batch of the migration
      fps.push_back(randomFingerprint(100 + k));
      ids.push_back(store->addScan({.map = "m", .robot = "r", .session = "s", .seq = k, .fingerprint = &fps.back()}));
    }
  }
  pg::Conn conn(backend_.options().path);
  const std::vector<float> old(static_cast<std::size_t>(dim), 0.05f);
  const std::span<const std::uint8_t> old_bytes(reinterpret_cast<const std::uint8_t*>(old.data()),
                                                old.size() * sizeof(float));
  for (std::size_t k = 0; k + 1 < ids.size(); ++k) {
    const auto blob = test::olderFormatBlob(fps[k], k % 2 ? 1u : 2u, old);
    conn.query("UPDATE scan_blobs SET fingerprint = $1 WHERE scan_id = $2",
               {std::span<const std::uint8_t>(blob), ids[k]});
    conn.query("UPDATE scans SET descriptor = $1 WHERE id = $2", {old_bytes, ids[k]});
  }
  const std::vector<std::uint8_t> junk{1, 2, 3};
  conn.query("UPDATE scan_blobs SET fingerprint = $1 WHERE scan_id = $2",
             {std::span<const std::uint8_t>(junk), ids.back()});
  exec(
      "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN retired_bytes; "
      "ALTER TABLE loops DROP COLUMN probability");
  exec("UPDATE sglc_meta SET value = '1' WHERE key = 'schema_version'");

  auto store = backend_.open();
  EXPECT_EQ(conn.query("SELECT value FROM sglc_meta WHERE key = 'schema_version'").text(0, 0), "5");
  const DescriptorConfig defaults;
  for (std::size_t k = 0; k + 1 < ids.size(); k += 37) {
    SCOPED_TRACE("scan " + std::to_string(k));
    const auto& f = fps[k];
    const auto expected = scanDescriptor(
        f.nodes, structureSpectrum(f.background, f.background_cell, f.layout.rings, f.layout.orders, defaults),
        f.layout, f.d_max, f.d_i, defaults.background_weight);
    const auto fp = store->fingerprint(ids[k]);
    ASSERT_TRUE(fp);
    ASSERT_EQ(fp->descriptor.size(), expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i) EXPECT_NEAR(fp->descriptor[i], expected[i], 1e-6) << i;
    const auto found = hits(*store, *fp, 1);
    ASSERT_EQ(found.size(), 1u);
    EXPECT_EQ(found[0], ids[k]);  // the index holds the new descriptor, not the old one
  }
  EXPECT_EQ(errorCode([&] { store->fingerprint(ids.back()); }), StorageError::Code::kCorrupt);
  EXPECT_EQ(store->stats("m").scans, static_cast<std::int64_t>(ids.size()));
}

TEST_F(PostgresStore, DamagedRowsAreCorruptNotServed) {
  std::int64_t a = 0, b = 0;
  {
    auto store = backend_.open();
    const auto fp = randomFingerprint(5);
    store->createMap("m", static_cast<int>(fp.descriptor.size()));
    a = store->addScan({.map = "m", .robot = "r", .session = "s", .seq = 0, .fingerprint = &fp});
    b = store->addScan({.map = "m", .robot = "r", .session = "s", .seq = 1, .fingerprint = &fp});
    store->addLoop("m", {0, b, a, Mat4d::Identity(), 0.8, 0.9, 0.05, 12});
    EXPECT_EQ(store->integrityCheck(), "ok");
  }
  // The eighth double becomes a NaN (0x7FF8000000000000, little-endian).
  exec("UPDATE loops SET t = overlay(t placing '\\x000000000000f87f'::bytea from 57 for 8)");
  exec("UPDATE scan_blobs SET fingerprint = '\\x0102'::bytea WHERE scan_id = " + std::to_string(a));
  {
    auto store = backend_.open();
    EXPECT_EQ(errorCode([&] { store->loops("m"); }), StorageError::Code::kCorrupt);
    EXPECT_EQ(errorCode([&] { store->fingerprint(a); }), StorageError::Code::kCorrupt);
    EXPECT_NE(store->fingerprint(b), nullptr);
  }
  exec("UPDATE scans SET descriptor = '\\x00'::bytea WHERE id = " + std::to_string(b));
  EXPECT_EQ(errorCode([&] { backend_.open(); }), StorageError::Code::kCorrupt);
}

// Two stores on one database, as two replicas are: each finds the other's scans, sees its deletions, creates
// no second map of a name, and ids stay unique and in commit order.
TEST_F(PostgresStore, ReplicasSeeEachOthersWrites) {
  auto a = backend_.open();
  auto b = backend_.open();
  const auto dim = static_cast<int>(randomFingerprint(1).descriptor.size());
  const auto map = a->createMap("m", dim);
  EXPECT_EQ(b->createMap("m", dim).id, map.id);  // b catches up before it writes: the same map
  std::vector<Fingerprint> fps;
  for (int i = 0; i < 20; ++i) fps.push_back(randomFingerprint(100 + static_cast<std::uint64_t>(i)));
  std::vector<std::int64_t> ids;
  for (int i = 0; i < 20; ++i) {
    auto& store = i % 2 ? *b : *a;  // alternate writers, one robot and session
    ids.push_back(store.addScan({.map = "m", .robot = "r", .session = "s", .seq = i, .fingerprint = &fps[i]}));
  }
  EXPECT_TRUE(std::is_sorted(ids.begin(), ids.end()));
  EXPECT_EQ(std::set<std::int64_t>(ids.begin(), ids.end()).size(), ids.size());
  // Each replica finds every scan, the other's included, first for its own descriptor.
  for (auto* store : {a.get(), b.get()}) {
    ASSERT_TRUE(eventually([&] { return store->stats("m").index_entries == 20; }));
    for (int i = 0; i < 20; ++i) EXPECT_EQ(hits(*store, fps[i]).front(), ids[i]);
  }
  EXPECT_EQ(
      errorCode([&] { b->addScan({.map = "m", .robot = "r", .session = "s", .seq = 4, .fingerprint = &fps[0]}); }),
      StorageError::Code::kAlreadyExists);
  // A deletion on one is followed on the other, index and cache alike.
  ASSERT_NE(a->fingerprint(ids[3]), nullptr);
  EXPECT_EQ(b->deleteRobot("m", "r"), 20);
  ASSERT_TRUE(eventually([&] { return a->stats("m").index_entries == 0; }));
  EXPECT_TRUE(hits(*a, fps[3]).empty());
  EXPECT_EQ(a->fingerprint(ids[3]), nullptr);
  EXPECT_TRUE(a->listRobots("m").empty());
  // A map deleted by one and created again: the other sees the new map, empty, under a new id.
  a->deleteMap("m");
  const auto again = b->createMap("m", dim);
  EXPECT_GT(again.id, map.id);
  ASSERT_TRUE(eventually([&] {
    const auto m = a->findMap("m");
    return m && m->id == again.id;
  }));
  EXPECT_EQ(a->stats("m").index_entries, 0);
  EXPECT_EQ(a->integrityCheck(), "ok");
}

// Lifelong maps: one replica retires a place's surplus scans while another ingests into the same place (new scans
// with loops to the scans being retired). The write lock orders the two; neither leaves a dangling loop or place,
// and both replicas' indexes lose the retired scans.
TEST_F(PostgresStore, ARetirementAndAnIngestIntoItsPlacesOnTwoReplicasStayConsistent) {
  auto a = backend_.open();
  auto b = backend_.open();
  const auto dim = static_cast<int>(randomFingerprint(1).descriptor.size());
  a->createMap("m", dim);
  b->createMap("m", dim);
  constexpr int kN = 40;
  std::vector<Fingerprint> fps;
  for (int i = 0; i < 3 * kN; ++i) fps.push_back(randomFingerprint(500 + static_cast<std::uint64_t>(i), 6));
  std::vector<std::int64_t> kept, surplus;
  std::vector<PlaceRecord> places;
  for (int i = 0; i < kN; ++i) {
    kept.push_back(a->addScan({.map = "m", .robot = "a", .session = "s", .seq = i, .fingerprint = &fps[i]}));
    surplus.push_back(a->addScan({.map = "m", .robot = "b", .session = "s", .seq = i, .fingerprint = &fps[kN + i]}));
    places.push_back({kept.back(), kept.back(), true});
    places.push_back({surplus.back(), kept.back(), false});
  }
  a->setPlaces("m", places);
  std::atomic<int> refused{0};
  auto ingest = std::async(std::launch::async, [&] {
    for (int i = 0; i < kN; ++i) {
      const auto id = b->addScan({.map = "m", .robot = "c", .session = "s", .seq = i, .fingerprint = &fps[2 * kN + i]});
      try {  // a loop to a scan retired meanwhile is refused (kNotFound), as the ingest path records it
        b->addLoop("m", {0, id, surplus[i], Mat4d::Identity(), 0.5, 0.6, 0.1, 9});
      } catch (const StorageError& e) {
        EXPECT_EQ(e.code(), StorageError::Code::kNotFound) << e.what();
        ++refused;
      }
      b->setPlaces("m", {{id, kept[i], false}});
    }
  });
  const auto retired = a->retireScans("m", surplus, {});
  ingest.get();
  EXPECT_EQ(retired.scans, kN);
  for (auto* store : {a.get(), b.get()}) {
    ASSERT_TRUE(eventually([&] { return store->stats("m").index_entries == 2 * kN; }));
    const auto st = store->stats("m");
    EXPECT_EQ(st.scans, 2 * kN);
    EXPECT_EQ(st.retired_scans, kN);
    EXPECT_EQ(st.places, kN);
    EXPECT_EQ(store->places("m").size(), static_cast<std::size_t>(2 * kN));
    for (const auto id : surplus) EXPECT_EQ(store->fingerprint(id), nullptr);
    std::set<std::int64_t> ids;
    for (const auto& n : store->graphNodes("m")) ids.insert(n.scan_id);
    for (const auto& l : store->loops("m")) EXPECT_TRUE(ids.count(l.query_scan) && ids.count(l.candidate_scan));
  }
  RecordProperty("loops_refused", refused.load());
  EXPECT_EQ(a->integrityCheck(), "ok");
}

// Ends the store's server connections and waits until those backends are gone (their sockets closed). The store
// reconnects at once (its follower does), so it waits for the ended ones, not for none at all.
void killConnections(const std::string& url) {
  pg::Conn admin(url);
  const auto r =
      admin.query("SELECT pid FROM pg_stat_activity WHERE datname = current_database() AND pid <> pg_backend_pid()");
  std::string pids = "{";
  for (int i = 0; i < r.rows(); ++i) pids += (i ? "," : "") + std::to_string(r.i64(i, 0));
  pids += "}";
  admin.query("SELECT pg_terminate_backend(pid) FROM unnest($1::int[]) AS pid", {pids});
  ASSERT_TRUE(eventually([&] {
    return admin.query("SELECT count(*) FROM pg_stat_activity WHERE pid = ANY($1::int[])", {pids}).i64(0, 0) == 0;
  }));
}

// The server restarting (here: every connection of the store ended by the server) costs nothing: idle
// connections are checked before use and re-established with their session settings, and a write after it
// still gives up on a held lock after busy_timeout_ms instead of waiting for ever.
TEST_F(PostgresStore, LostConnectionsAreReestablishedWithTheirSettings) {
  auto o = backend_.options();
  o.busy_timeout_ms = 300;
  auto store = MapStore::open(o);
  const auto fp = randomFingerprint(9);
  store->createMap("m", static_cast<int>(fp.descriptor.size()));
  const auto id = store->addScan({.map = "m", .robot = "r", .session = "s", .seq = 0, .fingerprint = &fp});
  {
    std::vector<std::thread> readers;  // several pooled reader connections
    for (int i = 0; i < 4; ++i) readers.emplace_back([&] { EXPECT_TRUE(store->scanInfo(id)); });
    for (auto& t : readers) t.join();
  }
  killConnections(o.path);
  EXPECT_TRUE(store->scanInfo(id));
  EXPECT_TRUE(store->scanInfo(id));
  EXPECT_NO_THROW(store->addScan({.map = "m", .robot = "r", .session = "s", .seq = 1, .fingerprint = &fp}));
  EXPECT_EQ(store->stats("m").scans, 2);
  EXPECT_EQ(store->stats("m").index_entries, 2);
  // Another process holds the write lock: after the reconnect, the writer's lock_timeout still applies.
  killConnections(o.path);
  pg::Conn holder(o.path);
  holder.query("SELECT pg_advisory_lock($1, $2)", {pg::kLockSpace, pg::kWriteLock});
  std::promise<void> answered;
  std::thread release([&, done = answered.get_future()] {
    done.wait_for(std::chrono::seconds(20));  // the write should give up long before; if not, do not hang
    holder.query("SELECT pg_advisory_unlock($1, $2)", {pg::kLockSpace, pg::kWriteLock});
  });
  EXPECT_EQ(
      errorCode([&] { store->addScan({.map = "m", .robot = "r", .session = "s", .seq = 2, .fingerprint = &fp}); }),
      StorageError::Code::kBusy);
  answered.set_value();
  release.join();
}

// What PostgreSQL stores differently is refused or handled with the right code: names that are not UTF-8
// (text columns), map ids past 2^31, and the size limit, which deletions free again.
TEST_F(PostgresStore, EdgesOfTheTypesAndTheSizeLimit) {
  auto o = backend_.options();
  o.max_db_mb = 0.3;
  auto store = MapStore::open(o);
  const auto fp = randomFingerprint(3, 40);
  const auto dim = static_cast<int>(fp.descriptor.size());
  exec("ALTER SEQUENCE maps_id_seq RESTART WITH 3000000000");
  EXPECT_GT(store->createMap("m", dim).id, std::int64_t{1} << 31);
  EXPECT_EQ(store->stats("m").scans, 0);
  EXPECT_EQ(errorCode([&] { store->addScan({.map = "m", .robot = "r\xff", .session = "s", .fingerprint = &fp}); }),
            StorageError::Code::kInvalidArgument);
  int stored = 0;
  for (bool full = false; !full && stored < 1000;) {
    try {
      store->addScan({.map = "m", .robot = "r", .session = "s", .seq = stored, .fingerprint = &fp});
      ++stored;
    } catch (const StorageError& e) {
      EXPECT_EQ(e.code(), StorageError::Code::kFull) << e.what();
      full = true;
    }
  }
  ASSERT_GT(stored, 2);
  ASSERT_LT(stored, 1000) << "the limit was never reached";
  EXPECT_EQ(store->deleteSession("m", "r", "s"), stored);
  EXPECT_NO_THROW(store->addScan({.map = "m", .robot = "r", .session = "t", .seq = 0, .fingerprint = &fp}));
  EXPECT_EQ(store->integrityCheck(), "ok");
}

}  // namespace
}  // namespace sglc::storage

namespace sglc::storage {
namespace {

// One process at a time solves a map's pose graph; the right goes with the store that holds it.
TEST_F(PostgresStore, OneStoreAtATimeHoldsAMapsGraphAndItsCloseFreesIt) {
  using Claim = MapStore::GraphClaim;
  auto a = backend_.open();
  auto b = backend_.open();
  const auto id = a->createMap("m", 8).id;
  const auto other = a->createMap("n", 8).id;
  EXPECT_TRUE(a->shared());
  EXPECT_EQ(a->claimGraph(id), Claim::kTaken);
  EXPECT_EQ(a->claimGraph(id), Claim::kHeld);  // held since
  EXPECT_EQ(b->claimGraph(id), Claim::kElsewhere);
  EXPECT_EQ(b->claimGraph(other), Claim::kTaken);  // per map
  EXPECT_EQ(a->claimGraph(other), Claim::kElsewhere);
  a.reset();
  // The server frees a closed session's locks just after the close, not with it: b takes the map soon after.
  EXPECT_TRUE(eventually([&] { return b->claimGraph(id) == Claim::kTaken; }));
  // A lost connection loses the lock: the holder finds out on its next claim instead of solving beside another,
  // and a lock taken again says so (what the holder knew may be stale).
  auto c = backend_.open();
  EXPECT_EQ(c->claimGraph(id), Claim::kElsewhere);
  pg::Conn(backend_.options().path).exec(testing::kEndThisDatabasesLockHolders);
  EXPECT_TRUE(eventually([&] { return c->claimGraph(id) == Claim::kTaken; }));  // once the ended session is gone
  EXPECT_EQ(b->claimGraph(id), Claim::kElsewhere);
  EXPECT_EQ(b->claimGraph(other), Claim::kTaken);  // b lost its connection too: taken again, not "held"
}

}  // namespace
}  // namespace sglc::storage
