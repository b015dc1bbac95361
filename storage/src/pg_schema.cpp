// The PostgreSQL map database's schema and its forward migrations: the SQLite layout (schema.cpp) in
// PostgreSQL's types, plus the change journal that keeps replicas in step.
#include "pg_schema.hpp"

#include <iterator>

#include "pg_core.hpp"
#include "sglc/fingerprint.hpp"

namespace sglc::storage::pg {
namespace {

using Code = StorageError::Code;

// Scans whose fingerprint is of an older format than this build writes get the current descriptor in their
// indexed column, as the SQLite store's 5 -> 6 does (schema.cpp): the blob stays, and deserialize recomputes its
// descriptor whenever it is read. Blobs that do not load, or whose descriptor does not fit the map, stay as they
// were. Read in batches of ids, so that a large map never sits in memory at once.
void upgradeDescriptors(const Conn& db) {
  std::int64_t after = 0;
  for (;;) {
    const auto rows = db.query(
        "SELECT s.id, m.descriptor_dim, b.fingerprint FROM scans s JOIN maps m ON m.id = s.map_id"
        " JOIN scan_blobs b ON b.scan_id = s.id WHERE s.id > $1 ORDER BY s.id LIMIT 256",
        {after});
    if (rows.rows() == 0) return;
    for (int r = 0; r < rows.rows(); ++r) {
      after = rows.i64(r, 0);
      const auto blob = rows.blob(r, 2);
      if (fingerprintFormat(blob) >= kFingerprintVersion) continue;
      std::vector<float> d;
      try {
        d = deserialize(blob).descriptor;
      } catch (const std::exception&) {  // InputError, or bad_alloc for an absurd node count
        continue;
      }
      if (static_cast<std::int64_t>(d.size()) != rows.i64(r, 1)) continue;
      db.query(
          "UPDATE scans SET descriptor = $1 WHERE id = $2",
          {std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(d.data()), d.size() * sizeof(float)),
           after});
    }
  }
}

struct Migration {
  const char* sql;                  // run first
  void (*rewrite)(const Conn& db);  // then this, when set
};

// kMigrations[v] upgrades a database from schema v to v + 1 (version 0: no tables of ours yet).
const Migration kMigrations[] = {
    // 0 -> 1: the initial schema.
    {R"sql(
    CREATE TABLE sglc_meta(key text PRIMARY KEY, value text NOT NULL);
    CREATE TABLE maps(
      id bigserial PRIMARY KEY, name text NOT NULL UNIQUE, descriptor_dim integer NOT NULL,
      created_at double precision NOT NULL, graph_version bigint NOT NULL DEFAULT 0,
      graph_loop bigint NOT NULL DEFAULT 0, bytes bigint NOT NULL DEFAULT 0);
    CREATE TABLE robots(
      id bigserial PRIMARY KEY, map_id bigint NOT NULL REFERENCES maps(id), name text NOT NULL,
      UNIQUE(map_id, name));
    CREATE TABLE sessions(
      id bigserial PRIMARY KEY, robot_id bigint NOT NULL REFERENCES robots(id), name text NOT NULL,
      created_at double precision NOT NULL, UNIQUE(robot_id, name));
    CREATE TABLE scans(
      id bigserial PRIMARY KEY, map_id bigint NOT NULL REFERENCES maps(id),
      robot_id bigint NOT NULL REFERENCES robots(id), session_id bigint NOT NULL REFERENCES sessions(id),
      seq bigint NOT NULL, stamp double precision, pose bytea, descriptor bytea NOT NULL,
      fingerprint_bytes bigint NOT NULL, has_raw boolean NOT NULL, created_at double precision NOT NULL,
      UNIQUE(session_id, seq));
    CREATE INDEX scans_by_map ON scans(map_id, id);
    CREATE INDEX scans_by_robot ON scans(robot_id);
    -- Large payloads apart, so that rebuilding an index reads only the small rows above. They are packed
    -- floats that do not compress: stored out of line without trying.
    CREATE TABLE scan_blobs(scan_id bigint PRIMARY KEY REFERENCES scans(id), fingerprint bytea NOT NULL, raw bytea);
    ALTER TABLE scan_blobs ALTER COLUMN fingerprint SET STORAGE EXTERNAL, ALTER COLUMN raw SET STORAGE EXTERNAL;
    CREATE TABLE loops(
      id bigserial PRIMARY KEY, map_id bigint NOT NULL REFERENCES maps(id),
      query_scan bigint NOT NULL REFERENCES scans(id), candidate_scan bigint NOT NULL REFERENCES scans(id),
      t bytea NOT NULL, score double precision NOT NULL, inliers integer NOT NULL, fitness double precision NOT NULL,
      rmse double precision NOT NULL, created_at double precision NOT NULL, information bytea,
      UNIQUE(query_scan, candidate_scan));
    CREATE INDEX loops_by_map ON loops(map_id, id);
    CREATE INDEX loops_by_candidate ON loops(candidate_scan);
    CREATE TABLE optimised_poses(scan_id bigint PRIMARY KEY REFERENCES scans(id), pose bytea NOT NULL);
    CREATE TABLE session_frames(
      session_id bigint PRIMARY KEY REFERENCES sessions(id), t bytea NOT NULL, connected boolean NOT NULL);
    CREATE TABLE sglc_changes(
      id bigserial PRIMARY KEY, map_id bigint NOT NULL, kind smallint NOT NULL, ref bigint NOT NULL);
    )sql",
     nullptr},
    // 1 -> 2: the structure spectrum in the scan descriptors (fingerprint format 3).
    {"", upgradeDescriptors},
    // 2 -> 3: the settings each map's fingerprints are made with (map_settings.hpp). Existing maps get none
    // here: a server records its own with them right after opening (MapStore::recordSettings).
    {R"sql(
    ALTER TABLE maps ADD COLUMN IF NOT EXISTS settings_hash text;
    CREATE TABLE IF NOT EXISTS map_settings(
      map_id bigint NOT NULL REFERENCES maps(id) ON DELETE CASCADE, position integer NOT NULL, key text NOT NULL,
      value text NOT NULL, PRIMARY KEY(map_id, position));
    )sql",
     nullptr},
    // 3 -> 4: the loop model's probability of each loop (NULL for loops recorded before: unknown).
    {R"sql(
    ALTER TABLE loops ADD COLUMN probability double precision;
    )sql",
     nullptr},
    // 4 -> 5: places of lifelong maps (gone with their scans), and each map's retired totals.
    {R"sql(
    CREATE TABLE places(
      scan_id bigint PRIMARY KEY REFERENCES scans(id) ON DELETE CASCADE,
      map_id bigint NOT NULL REFERENCES maps(id) ON DELETE CASCADE, place_id bigint NOT NULL,
      kept boolean NOT NULL);
    CREATE INDEX places_by_place ON places(map_id, place_id);
    ALTER TABLE maps ADD COLUMN retired_scans bigint NOT NULL DEFAULT 0;
    ALTER TABLE maps ADD COLUMN retired_bytes bigint NOT NULL DEFAULT 0;
    )sql",
     nullptr},
};

// The schema version of the database, 0 for one without our tables; kCorrupt for a database that holds
// another application's tables, kNewerSchema for one written by a newer build.
std::int64_t checkedVersion(const Conn& db, const std::string& url) {
  const auto ours = db.query("SELECT to_regclass('sglc_meta') IS NOT NULL");
  if (!ours.boolean(0, 0)) {
    const auto tables = db.query("SELECT count(*) FROM pg_tables WHERE schemaname = current_schema()");
    if (tables.i64(0, 0) > 0)
      throw StorageError(Code::kCorrupt, url +
                                             ": the database holds other tables and no SGLC map; use a database of "
                                             "its own for the map");
    return 0;
  }
  const auto v = db.query("SELECT value FROM sglc_meta WHERE key = 'schema_version'");
  if (v.rows() != 1) throw StorageError(Code::kCorrupt, url + ": sglc_meta has no schema version");
  std::int64_t version = 0;
  try {
    version = std::stoll(v.text(0, 0));
  } catch (const std::exception&) {
    throw StorageError(Code::kCorrupt, url + ": sglc_meta holds a schema version that is not a number");
  }
  if (version > kSchemaVersion)
    throw StorageError(Code::kNewerSchema, url + ": schema version " + std::to_string(version) +
                                               " is newer than this build supports (" + std::to_string(kSchemaVersion) +
                                               "); upgrade the software");
  return version;
}

}  // namespace

static_assert(std::size(kMigrations) == kSchemaVersion, "one migration per schema version");

void openSchema(const Conn& db, const std::string& url) {
  // Replicas starting together: one migrates, the others wait for it and then find the current schema.
  db.query("SELECT pg_advisory_lock($1, $2)", {kLockSpace, kSchemaLock});
  try {
    const auto version = checkedVersion(db, url);
    for (auto v = version; v < kSchemaVersion; ++v) {
      Transaction tx(db);
      const auto& step = kMigrations[static_cast<std::size_t>(v)];
      if (*step.sql) db.exec(step.sql);
      if (step.rewrite) step.rewrite(db);
      db.query(
          "INSERT INTO sglc_meta(key, value) VALUES('schema_version', $1) ON CONFLICT(key) DO UPDATE SET "
          "value = excluded.value",
          {std::to_string(v + 1)});
      tx.commit();
    }
  } catch (...) {
    try {
      db.query("SELECT pg_advisory_unlock($1, $2)", {kLockSpace, kSchemaLock});
    } catch (const StorageError&) {
      // The connection is gone, and the session lock with it.
    }
    throw;
  }
  db.query("SELECT pg_advisory_unlock($1, $2)", {kLockSpace, kSchemaLock});
}

}  // namespace sglc::storage::pg
