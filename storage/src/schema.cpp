#include "schema.hpp"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <iterator>
#include <random>
#include <vector>

#include "sglc/fingerprint.hpp"

namespace sglc::storage {
namespace {

namespace fs = std::filesystem;
using Code = StorageError::Code;

constexpr std::int32_t kApplicationId = 0x53474C43;  // "SGLC": marks our SQLite files

// Scans whose fingerprint is of an older format than this build writes get the current descriptor in their
// indexed column (5 -> 6: format 1 had hard-binned scan-descriptor edges, formats 1 and 2 a ring key where the
// structure spectrum is now). The blob itself stays: deserialize recomputes its descriptor whenever
// it is read, so only the small rows are written. A blob that does not load, or whose descriptor does not fit its
// map, is left as it was (reading it reports it, as before). Maps' generations move, so index snapshots are
// rebuilt.
void upgradeDescriptors(const sql::Db& db) {
  std::vector<std::pair<std::int64_t, std::int64_t>> scans;  // scan id, its map's descriptor dimension
  {
    sql::Stmt st(db, "SELECT s.id, m.descriptor_dim FROM scans s JOIN maps m ON m.id = s.map_id ORDER BY s.id");
    while (st.step()) scans.emplace_back(st.i64(0), st.i64(1));
  }
  sql::Stmt read(db, "SELECT fingerprint FROM scan_blobs WHERE scan_id = ?");
  sql::Stmt write(db, "UPDATE scans SET descriptor = ? WHERE id = ?");
  for (const auto& [id, dim] : scans) {
    read.reset();
    read.bind(1, id);
    if (!read.step() || fingerprintFormat(read.blob(0)) >= kFingerprintVersion) continue;
    std::vector<float> d;
    try {
      d = deserialize(read.blob(0)).descriptor;
    } catch (const std::exception&) {  // InputError, or bad_alloc for an absurd node count
      continue;
    }
    if (static_cast<std::int64_t>(d.size()) != dim) continue;
    write.reset();
    write.bindBlob(1, {reinterpret_cast<const std::uint8_t*>(d.data()), d.size() * sizeof(float)}).bind(2, id).run();
  }
  db.exec("UPDATE maps SET generation = generation + 1");
}

// 6 -> 7: each map's fingerprint settings (map_settings.hpp). The maps of the file get none here: this step
// knows no engine settings; a server records its own with them right after opening (MapStore::recordSettings).
// Tolerates a file that has the column and table already (one turned back to an older version by lowering
// user_version, as tests do): SQLite has no ADD COLUMN IF NOT EXISTS.
void addMapSettings(const sql::Db& db) {
  bool has_column = false;
  {
    sql::Stmt st(db, "SELECT 1 FROM pragma_table_info('maps') WHERE name = 'settings_hash'");
    has_column = st.step();
  }
  if (!has_column) db.exec("ALTER TABLE maps ADD COLUMN settings_hash TEXT");
  db.exec(R"sql(
    CREATE TABLE IF NOT EXISTS map_settings(
      map_id INTEGER NOT NULL REFERENCES maps(id) ON DELETE CASCADE, position INTEGER NOT NULL,
      key TEXT NOT NULL, value TEXT NOT NULL, PRIMARY KEY(map_id, position));
    )sql");
}

struct Migration {
  const char* sql;                     // run first
  void (*rewrite)(const sql::Db& db);  // then this, when set
};

// Forward migrations: kMigrations[v] upgrades a file from user_version v to v + 1.
const Migration kMigrations[] = {
    // 0 -> 1: the initial schema.
    {R"sql(
    CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
    CREATE TABLE maps(
      id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, descriptor_dim INTEGER NOT NULL,
      created_at REAL NOT NULL, generation INTEGER NOT NULL DEFAULT 0);
    CREATE TABLE robots(
      id INTEGER PRIMARY KEY, map_id INTEGER NOT NULL REFERENCES maps(id), name TEXT NOT NULL,
      UNIQUE(map_id, name));
    CREATE TABLE sessions(
      id INTEGER PRIMARY KEY, robot_id INTEGER NOT NULL REFERENCES robots(id), name TEXT NOT NULL,
      created_at REAL NOT NULL, UNIQUE(robot_id, name));
    CREATE TABLE scans(
      id INTEGER PRIMARY KEY AUTOINCREMENT, map_id INTEGER NOT NULL REFERENCES maps(id),
      robot_id INTEGER NOT NULL REFERENCES robots(id), session_id INTEGER NOT NULL REFERENCES sessions(id),
      seq INTEGER NOT NULL, stamp REAL, pose BLOB, descriptor BLOB NOT NULL,
      fingerprint_bytes INTEGER NOT NULL, has_raw INTEGER NOT NULL, created_at REAL NOT NULL,
      UNIQUE(session_id, seq));
    CREATE INDEX scans_by_map ON scans(map_id, id);
    -- Large payloads apart, so that rebuilding the index reads only the small rows above.
    CREATE TABLE scan_blobs(
      scan_id INTEGER PRIMARY KEY REFERENCES scans(id), fingerprint BLOB NOT NULL, raw BLOB);
    )sql",
     nullptr},
    // 1 -> 2: the pose graph (verified loops, optimised poses, session frames).
    {R"sql(
    CREATE TABLE loops(
      id INTEGER PRIMARY KEY AUTOINCREMENT, map_id INTEGER NOT NULL REFERENCES maps(id),
      query_scan INTEGER NOT NULL REFERENCES scans(id), candidate_scan INTEGER NOT NULL REFERENCES scans(id),
      t BLOB NOT NULL, score REAL NOT NULL, inliers INTEGER NOT NULL, fitness REAL NOT NULL, rmse REAL NOT NULL,
      created_at REAL NOT NULL, UNIQUE(query_scan, candidate_scan));
    CREATE INDEX loops_by_map ON loops(map_id, id);
    CREATE INDEX loops_by_candidate ON loops(candidate_scan);
    CREATE TABLE optimised_poses(scan_id INTEGER PRIMARY KEY REFERENCES scans(id), pose BLOB NOT NULL);
    CREATE TABLE session_frames(
      session_id INTEGER PRIMARY KEY REFERENCES sessions(id), t BLOB NOT NULL, connected INTEGER NOT NULL);
    ALTER TABLE maps ADD COLUMN graph_version INTEGER NOT NULL DEFAULT 0;
    )sql",
     nullptr},
    // 2 -> 3: the information matrix of each loop's pose (36 doubles; NULL for loops recorded before).
    {R"sql(
    ALTER TABLE loops ADD COLUMN information BLOB;
    )sql",
     nullptr},
    // 3 -> 4: the last loop the stored optimised poses account for (0: unknown, all loops are new).
    {R"sql(
    ALTER TABLE maps ADD COLUMN graph_loop INTEGER NOT NULL DEFAULT 0;
    )sql",
     nullptr},
    // 4 -> 5: soft-binned scan descriptors (fingerprint format 2) in the index. Since schema 6 the step 5 -> 6
    // writes the current descriptor of every older format, so this one has nothing left to do.
    {"", nullptr},
    // 5 -> 6: the structure spectrum in the scan descriptors (fingerprint format 3).
    {"", upgradeDescriptors},
    // 6 -> 7: the settings each map's fingerprints are made with.
    {"", addMapSettings},
    // 7 -> 8: the loop model's probability of each loop (NULL for loops recorded before: unknown).
    {R"sql(
    ALTER TABLE loops ADD COLUMN probability REAL;
    )sql",
     nullptr},
    // 8 -> 9: places of lifelong maps, and each map's retired totals.
    {R"sql(
    CREATE TABLE places(
      scan_id INTEGER PRIMARY KEY REFERENCES scans(id), map_id INTEGER NOT NULL REFERENCES maps(id),
      place_id INTEGER NOT NULL, kept INTEGER NOT NULL);
    CREATE INDEX places_by_place ON places(map_id, place_id);
    ALTER TABLE maps ADD COLUMN retired_scans INTEGER NOT NULL DEFAULT 0;
    ALTER TABLE maps ADD COLUMN retired_bytes INTEGER NOT NULL DEFAULT 0;
    )sql",
     nullptr},
};
static_assert(std::size(kMigrations) == kSchemaVersion, "one migration per schema version");

// The file may be opened for writing: the path is a file (or can become one) in a writable place.
void checkPath(const std::string& file) {
  if (file.empty()) throw StorageError(Code::kInvalidArgument, "database path is empty");
  const fs::path path(file);
  std::error_code ec;
  const bool existed = fs::exists(path, ec);
  if (existed && fs::is_directory(path, ec))
    throw StorageError(Code::kInvalidArgument, file + ": is a directory, not a database file");
  if (!existed && path.has_parent_path()) {
    fs::create_directories(path.parent_path(), ec);
    if (ec)
      throw StorageError(
          ec == std::errc::permission_denied || ec == std::errc::read_only_file_system ? Code::kReadOnly : Code::kIo,
          path.parent_path().string() + ": cannot create directory: " + ec.message());
  }
  if (!existed) {
    const auto dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
    if (::access(dir.c_str(), W_OK) != 0)
      throw StorageError(Code::kReadOnly, dir.string() + ": directory is not writable, cannot create " + file);
  } else if (::access(file.c_str(), W_OK) != 0) {
    throw StorageError(Code::kReadOnly, file + ": database file is not writable");
  }
}

// The file is an SGLC map (or a new, empty SQLite file) of a schema this build reads; returns its version.
std::int64_t checkedVersion(const sql::Db& db, const std::string& file) {
  std::int64_t app_id = 0, version = 0, objects = 0;
  try {
    sql::Stmt a(db, "PRAGMA application_id");
    if (a.step()) app_id = a.i64(0);
    sql::Stmt v(db, "PRAGMA user_version");
    if (v.step()) version = v.i64(0);
    sql::Stmt o(db, "SELECT count(*) FROM sqlite_master");
    if (o.step()) objects = o.i64(0);
  } catch (const StorageError& e) {
    if (e.code() == Code::kCorrupt)
      throw StorageError(Code::kCorrupt, file + ": not an SGLC map database (not SQLite, or damaged)");
    throw;
  }
  if (app_id != kApplicationId && !(app_id == 0 && objects == 0))
    throw StorageError(Code::kCorrupt, file + ": a foreign SQLite database, not an SGLC map");
  if (version > kSchemaVersion)
    throw StorageError(Code::kNewerSchema, file + ": schema version " + std::to_string(version) +
                                               " is newer than this build supports (" + std::to_string(kSchemaVersion) +
                                               "); upgrade the software");
  return version;
}

void configure(const sql::Db& db, const StoreOptions& options) {
  // WAL lets readers run during a write; it must be set outside a transaction.
  {
    sql::Stmt wal(db, "PRAGMA journal_mode=WAL");
    if (!wal.step() || wal.text(0) != "wal")
      throw StorageError(Code::kIo, options.path + ": cannot switch to WAL journal mode");
  }
  const char* sync = options.sync == StoreOptions::Sync::kFull     ? "FULL"
                     : options.sync == StoreOptions::Sync::kNormal ? "NORMAL"
                                                                   : "OFF";
  db.exec(std::string("PRAGMA synchronous=") + sync);
  db.exec("PRAGMA foreign_keys=ON");
  if (options.max_db_mb > 0) {
    const auto pages = static_cast<std::int64_t>(options.max_db_mb * 1024 * 1024 / 4096);
    db.exec("PRAGMA max_page_count=" + std::to_string(std::max<std::int64_t>(pages, 16)));
  }
}

// Forward migrations from `version`, each in its own transaction with the version bump.
void migrate(const sql::Db& db, std::int64_t version) {
  for (auto v = version; v < kSchemaVersion; ++v) {
    sql::Transaction tx(db);
    const auto& step = kMigrations[static_cast<std::size_t>(v)];
    db.exec(step.sql);
    if (step.rewrite) step.rewrite(db);
    if (v == 0) {
      std::random_device rd;
      const auto token = (static_cast<std::uint64_t>(rd()) << 32) ^ rd();
      sql::Stmt(db, "INSERT INTO meta(key, value) VALUES('token', ?)").bind(1, std::to_string(token)).run();
      db.exec("PRAGMA application_id=" + std::to_string(kApplicationId));
    }
    db.exec("PRAGMA user_version=" + std::to_string(v + 1));
    tx.commit();
  }
}

}  // namespace

OpenedDatabase openDatabase(const StoreOptions& options) {
  checkPath(options.path);
  OpenedDatabase db;
  db.lock = ProcessLock(options.path);
  db.writer = sql::Db(options.path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, options.busy_timeout_ms);
  const auto version = checkedVersion(db.writer, options.path);
  configure(db.writer, options);
  migrate(db.writer, version);
  {
    sql::Stmt t(db.writer, "SELECT value FROM meta WHERE key = 'token'");
    if (!t.step()) throw StorageError(Code::kCorrupt, options.path + ": meta table has no token");
    db.token = t.text(0);
  }
  return db;
}

}  // namespace sglc::storage
