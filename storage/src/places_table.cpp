#include "places_table.hpp"

#include <array>
#include <unordered_set>

#include "blob_codec.hpp"
#include "validate.hpp"

namespace sglc::storage::places_table {
namespace {

using Code = StorageError::Code;

PlaceRecord readRow(const sql::Stmt& st) {
  PlaceRecord r;
  r.scan_id = st.i64(0);
  r.place_id = st.i64(1);
  r.kept = st.i64(2) != 0;
  r.session_id = st.i64(3);
  r.seq = st.i64(4);
  r.added_at = st.f64(5);
  return r;
}

constexpr const char* kSelect =
    "SELECT p.scan_id, p.place_id, p.kept, s.session_id, s.seq, s.created_at FROM places p"
    " JOIN scans s ON s.id = p.scan_id";

// Inserts `loop` unless the pair has a loop already (inside the caller's transaction). Returns whether it did.
bool insertLoop(const sql::Db& db, std::int64_t map_id, const LoopRecord& loop) {
  const auto t = blob::fromPose(loop.T);
  const auto info = loop.information ? blob::fromInformation(*loop.information) : std::vector<std::uint8_t>{};
  sql::Stmt st(db,
               "INSERT OR IGNORE INTO loops(map_id, query_scan, candidate_scan, t, score, inliers, fitness, rmse,"
               " created_at, information, probability) SELECT ?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11"
               " WHERE (SELECT count(*) FROM scans WHERE map_id = ?1 AND id IN (?2, ?3)) = 2"
               " AND NOT EXISTS(SELECT 1 FROM loops WHERE query_scan = ?3 AND candidate_scan = ?2)");
  st.bind(1, map_id).bind(2, loop.query_scan).bind(3, loop.candidate_scan).bindBlob(4, t).bind(5, loop.score);
  st.bind(6, static_cast<std::int64_t>(loop.inliers)).bind(7, loop.fitness).bind(8, loop.rmse).bind(9, nowSeconds());
  if (loop.information)
    st.bindBlob(10, info);
  else
    st.bindNull(10);
  if (loop.probability)
    st.bind(11, *loop.probability);
  else
    st.bindNull(11);
  st.run();
  return sqlite3_changes(db.get()) > 0;
}

}  // namespace

void set(StoreCore& core, const std::string& map, const std::vector<PlaceRecord>& records) {
  std::lock_guard write(core.write_mutex);
  const auto map_id = core.mapId(map);
  const auto& db = core.writer();
  sql::Transaction tx(db);
  sql::Stmt st(db,
               "INSERT OR REPLACE INTO places(scan_id, map_id, place_id, kept) SELECT ?1, ?2, ?3, ?4"
               " WHERE EXISTS(SELECT 1 FROM scans WHERE id = ?1 AND map_id = ?2)");
  for (const auto& r : records) {
    st.bind(1, r.scan_id).bind(2, map_id).bind(3, r.place_id).bind(4, static_cast<std::int64_t>(r.kept ? 1 : 0));
    st.run();
    if (sqlite3_changes(db.get()) == 0)
      throw StorageError(Code::kNotFound, "map '" + map + "' has no scan " + std::to_string(r.scan_id));
    st.reset();
  }
  tx.commit();
}

std::vector<PlaceRecord> all(const StoreCore& core, const std::string& map) {
  const auto map_id = core.mapId(map);
  auto reader = core.readers.acquire();
  const std::string text = std::string(kSelect) + " WHERE p.map_id = ? ORDER BY p.scan_id";
  sql::Stmt st(*reader, text.c_str());
  st.bind(1, map_id);
  std::vector<PlaceRecord> out;
  while (st.step()) out.push_back(readRow(st));
  return out;
}

std::optional<PlaceRecord> of(const StoreCore& core, std::int64_t scan_id) {
  auto reader = core.readers.acquire();
  const std::string text = std::string(kSelect) + " WHERE p.scan_id = ?";
  sql::Stmt st(*reader, text.c_str());
  st.bind(1, scan_id);
  if (!st.step()) return std::nullopt;
  return readRow(st);
}

std::int64_t versions(const StoreCore& core, const std::string& map, std::int64_t place_id) {
  const auto map_id = core.mapId(map);
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader, "SELECT count(*) FROM places WHERE map_id = ? AND place_id = ? AND kept = 1");
  st.bind(1, map_id).bind(2, place_id);
  return st.step() ? st.i64(0) : 0;
}

Retired retire(StoreCore& core, const std::string& map, const std::vector<std::int64_t>& scans,
               const std::vector<LoopRecord>& new_loops) {
  for (const auto& loop : new_loops) validate::loop(loop);
  std::lock_guard write(core.write_mutex);
  MapState* m;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(map);
  }
  const auto& db = core.writer();
  sql::Transaction tx(db);
  Retired out;
  std::unordered_set<std::int64_t> ids;
  {
    sql::Stmt find(db, "SELECT fingerprint_bytes FROM scans WHERE id = ? AND map_id = ?");
    for (const auto id : scans) {
      find.bind(1, id).bind(2, m->id);
      if (find.step() && ids.insert(id).second) out.bytes += find.i64(0);
      find.reset();
    }
  }
  static constexpr std::array<const char*, 5> kRows = {
      "DELETE FROM scan_blobs WHERE scan_id = ?1", "DELETE FROM loops WHERE query_scan = ?1 OR candidate_scan = ?1",
      "DELETE FROM optimised_poses WHERE scan_id = ?1", "DELETE FROM places WHERE scan_id = ?1",
      "DELETE FROM scans WHERE id = ?1"};
  for (const char* text : kRows) {
    sql::Stmt st(db, text);
    for (const auto id : ids) {
      st.bind(1, id).run();
      st.reset();
    }
  }
  for (const auto& loop : new_loops)
    if (insertLoop(db, m->id, loop)) ++out.loops_kept;
  out.scans = static_cast<std::int64_t>(ids.size());
  sql::Stmt(db,
            "UPDATE maps SET generation = generation + 1, retired_scans = retired_scans + ?2,"
            " retired_bytes = retired_bytes + ?3 WHERE id = ?1")
      .bind(1, m->id)
      .bind(2, out.scans)
      .bind(3, out.bytes)
      .run();
  std::unique_lock lock(core.state_mutex);
  tx.commit();
  m->generation += 1;
  m->deletions += 1;
  m->index->remove(ids);
  for (auto sid : ids) core.cache.erase(sid);
  return out;
}

void count(const sql::Db& db, std::int64_t map_id, Stats& s) {
  sql::Stmt p(db,
              "SELECT count(DISTINCT map_id || ':' || place_id), coalesce(sum(kept), 0) FROM places"
              " WHERE ?1 < 0 OR map_id = ?1");
  p.bind(1, map_id);
  if (p.step()) {
    s.places = p.i64(0);
    s.versions = p.i64(1);
  }
  sql::Stmt r(db,
              "SELECT coalesce(sum(retired_scans), 0), coalesce(sum(retired_bytes), 0) FROM maps"
              " WHERE ?1 < 0 OR id = ?1");
  r.bind(1, map_id);
  if (r.step()) {
    s.retired_scans = r.i64(0);
    s.retired_bytes = r.i64(1);
  }
}

}  // namespace sglc::storage::places_table
