// Places of lifelong maps in PostgreSQL (places_table.hpp is the SQLite twin): place records, and the
// retirement of scans with their loops moved to scans that stay, journalled scan by scan for the other replicas.
#include <unordered_set>

#include "blob_codec.hpp"
#include "pg_parts.hpp"
#include "validate.hpp"

namespace sglc::storage::pg::places {
namespace {

using Code = StorageError::Code;
using Bytes = std::span<const std::uint8_t>;

constexpr const char* kSelect =
    "SELECT p.scan_id, p.place_id, p.kept::int, s.session_id, s.seq, s.created_at FROM places p"
    " JOIN scans s ON s.id = p.scan_id";

PlaceRecord readRow(const Result& r, int i) {
  return {r.i64(i, 0), r.i64(i, 1), r.boolean(i, 2), r.i64(i, 3), r.i64(i, 4), r.f64(i, 5)};
}

// Inserts `loop` unless its pair has a loop already or an end is not in the map. Returns whether it did.
bool insertLoop(const Conn& db, std::int64_t map_id, const LoopRecord& loop) {
  const auto t = blob::fromPose(loop.T);
  const auto info = loop.information ? blob::fromInformation(*loop.information) : std::vector<std::uint8_t>{};
  return db.query(
               "INSERT INTO loops(map_id, query_scan, candidate_scan, t, score, inliers, fitness, rmse, created_at,"
               " information, probability) SELECT $1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11"
               " WHERE (SELECT count(*) FROM scans WHERE map_id = $1 AND id IN ($2, $3)) = 2"
               " AND NOT EXISTS(SELECT 1 FROM loops WHERE (query_scan = $2 AND candidate_scan = $3) OR"
               " (query_scan = $3 AND candidate_scan = $2)) RETURNING id",
               {map_id, loop.query_scan, loop.candidate_scan, Bytes(t), loop.score, loop.inliers, loop.fitness,
                loop.rmse, nowSeconds(), loop.information ? Param(Bytes(info)) : Param(),
                loop.probability ? Param(*loop.probability) : Param()})
             .rows() > 0;
}

}  // namespace

void set(Core& core, const std::string& map, const std::vector<PlaceRecord>& records) {
  WriteTx tx(core);
  const auto map_id = core.mapId(map);
  const auto& db = tx.conn();
  for (const auto& r : records) {
    const auto done = db.query(
        "INSERT INTO places(scan_id, map_id, place_id, kept) SELECT $1, $2, $3, $4::boolean"
        " WHERE EXISTS(SELECT 1 FROM scans WHERE id = $1 AND map_id = $2)"
        " ON CONFLICT(scan_id) DO UPDATE SET place_id = excluded.place_id, kept = excluded.kept RETURNING scan_id",
        {r.scan_id, map_id, r.place_id, r.kept ? "true" : "false"});
    if (done.rows() == 0)
      throw StorageError(Code::kNotFound, "map '" + map + "' has no scan " + std::to_string(r.scan_id));
  }
  tx.commit(0, [] {});
}

std::vector<PlaceRecord> all(const Core& core, const std::string& map) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  const std::string text = std::string(kSelect) + " WHERE p.map_id = $1 ORDER BY p.scan_id";
  const auto r = db->query(text.c_str(), {map_id});
  std::vector<PlaceRecord> out;
  out.reserve(static_cast<std::size_t>(r.rows()));
  for (int i = 0; i < r.rows(); ++i) out.push_back(readRow(r, i));
  return out;
}

std::optional<PlaceRecord> of(const Core& core, std::int64_t scan_id) {
  auto db = core.readers.acquire();
  const std::string text = std::string(kSelect) + " WHERE p.scan_id = $1";
  const auto r = db->query(text.c_str(), {scan_id});
  if (r.rows() == 0) return std::nullopt;
  return readRow(r, 0);
}

std::int64_t versions(const Core& core, const std::string& map, std::int64_t place_id) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  return db->query("SELECT count(*) FROM places WHERE map_id = $1 AND place_id = $2 AND kept", {map_id, place_id})
      .i64(0, 0);
}

Retired retire(Core& core, const std::string& map, const std::vector<std::int64_t>& scans,
               const std::vector<LoopRecord>& new_loops) {
  for (const auto& loop : new_loops) validate::loop(loop);
  // The write transaction holds the database-wide write lock: no replica ingests into, or retires from, any map
  // while it runs, and its journal tells them which scans left.
  WriteTx tx(core);
  MapState* m;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(map);
  }
  const auto& db = tx.conn();
  Retired out;
  // Set-based, as deletions are: a few statements whatever the number of scans, so the write lock that every
  // replica waits on is held for a few round trips.
  std::string list = "{";
  for (std::size_t i = 0; i < scans.size(); ++i) list += (i ? "," : "") + std::to_string(scans[i]);
  list += "}";
  const auto found = db.query(
      "SELECT s.id, s.fingerprint_bytes, s.fingerprint_bytes + octet_length(s.descriptor) +"
      " coalesce(octet_length(b.raw), 0) FROM scans s JOIN scan_blobs b ON b.scan_id = s.id"
      " WHERE s.id = ANY($1::bigint[]) AND s.map_id = $2 ORDER BY s.id",
      {list, m->id});
  std::unordered_set<std::int64_t> ids;
  std::int64_t stored = 0;
  list = "{";
  for (int i = 0; i < found.rows(); ++i) {
    ids.insert(found.i64(i, 0));
    out.bytes += found.i64(i, 1);
    stored += found.i64(i, 2);
    list += (i ? "," : "") + std::to_string(found.i64(i, 0));
  }
  list += "}";
  db.query("UPDATE maps SET bytes = greatest(0, bytes - $2) WHERE id = $1", {m->id, stored});
  for (const char* sql :
       {"DELETE FROM scan_blobs WHERE scan_id = ANY($1::bigint[])",
        "DELETE FROM loops WHERE query_scan = ANY($1::bigint[]) OR candidate_scan = ANY($1::bigint[])",
        "DELETE FROM optimised_poses WHERE scan_id = ANY($1::bigint[])",
        "DELETE FROM scans WHERE id = ANY($1::bigint[])"})
    db.query(sql, {list});
  const std::int64_t entry = ids.empty() ? 0 : tx.journalEach(Change::kScanRetired, m->id, list);
  for (const auto& loop : new_loops)
    if (insertLoop(db, m->id, loop)) ++out.loops_kept;
  out.scans = static_cast<std::int64_t>(ids.size());
  db.query("UPDATE maps SET retired_scans = retired_scans + $2, retired_bytes = retired_bytes + $3 WHERE id = $1",
           {m->id, out.scans, out.bytes});
  // The journal's own entries, applied here as other processes apply them.
  tx.commit(entry, [&] {
    m->index->remove(ids);
    m->deletions += 1;
    for (const auto sid : ids) core.cache.erase(sid);
  });
  return out;
}

void count(const Conn& db, std::int64_t map_id, Stats& s) {
  const auto p = db.query(
      "SELECT count(DISTINCT (map_id, place_id)), count(*) FILTER (WHERE kept) FROM places"
      " WHERE $1::bigint < 0 OR map_id = $1",
      {map_id});
  s.places = p.i64(0, 0);
  s.versions = p.i64(0, 1);
  const auto r = db.query(
      "SELECT coalesce(sum(retired_scans), 0)::bigint, coalesce(sum(retired_bytes), 0)::bigint FROM maps"
      " WHERE $1::bigint < 0 OR id = $1",
      {map_id});
  s.retired_scans = r.i64(0, 0);
  s.retired_bytes = r.i64(0, 1);
}

}  // namespace sglc::storage::pg::places
