// Scans in PostgreSQL: storing one (with its robot and session on first use), reading its row and blobs, and
// deleting a session's, a robot's or a map's scans with everything that hangs on them.
#include <array>
#include <cmath>

#include "blob_codec.hpp"
#include "pg_parts.hpp"
#include "sglc/fingerprint.hpp"
#include "validate.hpp"

namespace sglc::storage::pg::scans {
namespace {

using Code = StorageError::Code;

std::span<const std::uint8_t> bytes(const std::vector<float>& v) {
  return {reinterpret_cast<const std::uint8_t*>(v.data()), v.size() * sizeof(float)};
}

// The robot's and session's ids, inserting rows for new ones in the write's transaction.
struct Owner {
  std::int64_t robot_id = 0, session_id = 0;
};
Owner ownerOf(const Conn& db, const MapState& m, const NewScan& scan) {
  Owner o;
  if (auto it = m.robots.find(scan.robot); it != m.robots.end())
    o.robot_id = it->second;
  else
    o.robot_id = db.query("INSERT INTO robots(map_id, name) VALUES($1, $2) RETURNING id", {m.id, scan.robot}).i64(0, 0);
  if (auto it = m.sessions.find({o.robot_id, scan.session}); it != m.sessions.end())
    o.session_id = it->second;
  else
    o.session_id = db.query("INSERT INTO sessions(robot_id, name, created_at) VALUES($1, $2, $3) RETURNING id",
                            {o.robot_id, scan.session, nowSeconds()})
                       .i64(0, 0);
  return o;
}

std::int64_t insertRow(const Conn& db, std::int64_t map_id, const Owner& o, const NewScan& scan,
                       std::size_t fingerprint_bytes) {
  const auto pose = scan.odometry_pose ? blob::fromPose(*scan.odometry_pose) : std::vector<std::uint8_t>();
  try {
    return db
        .query(
            "INSERT INTO scans(map_id, robot_id, session_id, seq, stamp, pose, descriptor, fingerprint_bytes,"
            " has_raw, created_at) VALUES($1, $2, $3, $4, $5, $6, $7, $8, $9, $10) RETURNING id",
            {map_id, o.robot_id, o.session_id, scan.seq, scan.stamp ? Param(*scan.stamp) : Param(),
             scan.odometry_pose ? Param(std::span<const std::uint8_t>(pose)) : Param(),
             bytes(scan.fingerprint->descriptor), static_cast<std::int64_t>(fingerprint_bytes),
             scan.raw ? "true" : "false", nowSeconds()})
        .i64(0, 0);
  } catch (const StorageError& e) {
    if (e.code() == Code::kAlreadyExists)
      throw StorageError(Code::kAlreadyExists, "robot '" + scan.robot + "' session '" + scan.session +
                                                   "' already has a scan with seq " + std::to_string(scan.seq));
    throw;
  }
}

// The size limit (StoreOptions::max_db_mb) counts the bytes the scans store (fingerprints, descriptors, raw
// clouds), kept per map in the write's transaction: unlike the tables' size on disk it goes down when scans
// are deleted. PostgreSQL's own overhead comes on top.
void checkQuota(const Conn& db, const Core& core, std::int64_t incoming) {
  if (core.options.max_db_mb <= 0) return;
  const auto stored = db.query("SELECT coalesce(sum(bytes), 0)::bigint FROM maps").i64(0, 0);
  const double mb = static_cast<double>(stored + incoming) / (1024.0 * 1024.0);
  if (mb > core.options.max_db_mb)
    throw StorageError(Code::kFull, meaning(Code::kFull),
                       "the scans would take " + std::to_string(mb) + " MB, over the " +
                           std::to_string(core.options.max_db_mb) + " MB limit (store.max_db_mb)");
}

}  // namespace

std::int64_t add(Core& core, const NewScan& scan) {
  validate::scan(scan);
  const auto fingerprint = serialize(*scan.fingerprint);
  const auto raw = scan.raw ? blob::fromRawScan(*scan.raw) : std::vector<std::uint8_t>();
  WriteTx tx(core);  // applies others' writes first: the catalogue below is current
  MapState* m;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(scan.map);
  }
  const auto& descriptor = scan.fingerprint->descriptor;
  if (static_cast<int>(descriptor.size()) != m->dim)
    throw StorageError(Code::kInvalidArgument, "descriptor has " + std::to_string(descriptor.size()) +
                                                   " values, map '" + scan.map + "' needs " + std::to_string(m->dim));
  const auto& db = tx.conn();
  const auto payload = static_cast<std::int64_t>(fingerprint.size() + raw.size() + descriptor.size() * sizeof(float));
  checkQuota(db, core, payload);
  const auto owner = ownerOf(db, *m, scan);
  const auto id = insertRow(db, m->id, owner, scan, fingerprint.size());
  db.query("UPDATE maps SET bytes = bytes + $2 WHERE id = $1", {m->id, payload});
  db.query(
      "INSERT INTO scan_blobs(scan_id, fingerprint, raw) VALUES($1, $2, $3)",
      {id, std::span<const std::uint8_t>(fingerprint), scan.raw ? Param(std::span<const std::uint8_t>(raw)) : Param()});
  const auto entry = tx.journal(Change::kScanAdded, m->id, id);
  IndexEntry e{id, owner.robot_id, owner.session_id, scan.seq, scan.stamp ? *scan.stamp : std::nan(""), false};
  tx.commit(entry, [&] {
    m->robots[scan.robot] = owner.robot_id;
    m->sessions[{owner.robot_id, scan.session}] = owner.session_id;
    m->index->add(e, descriptor.data());
  });
  return id;
}

std::optional<ScanInfo> info(const Core& core, std::int64_t scan_id) {
  auto db = core.readers.acquire();
  const auto r = db->query(
      "SELECT m.name, rb.name, x.name, s.seq, s.stamp, s.pose, s.fingerprint_bytes, s.has_raw FROM scans s"
      " JOIN maps m ON m.id = s.map_id JOIN robots rb ON rb.id = s.robot_id JOIN sessions x ON x.id = s.session_id"
      " WHERE s.id = $1",
      {scan_id});
  if (r.rows() == 0) return std::nullopt;
  ScanInfo info;
  info.id = scan_id;
  info.map = r.text(0, 0);
  info.robot = r.text(0, 1);
  info.session = r.text(0, 2);
  info.seq = r.i64(0, 3);
  if (!r.isNull(0, 4)) info.stamp = r.f64(0, 4);
  if (!r.isNull(0, 5)) info.odometry_pose = blob::toPose(r.blob(0, 5));
  info.fingerprint_bytes = r.i64(0, 6);
  info.has_raw = r.boolean(0, 7);
  return info;
}

std::shared_ptr<const Fingerprint> fingerprint(const Core& core, std::int64_t scan_id) {
  if (auto hit = core.cache.get(scan_id)) return hit;
  std::shared_ptr<const Fingerprint> fp;
  {
    auto db = core.readers.acquire();
    const auto r = db->query("SELECT fingerprint FROM scan_blobs WHERE scan_id = $1", {scan_id});
    if (r.rows() == 0) return nullptr;
    try {
      fp = std::make_shared<const Fingerprint>(deserialize(r.blob(0, 0)));
    } catch (const InputError& e) {
      throw StorageError(Code::kCorrupt, "scan " + std::to_string(scan_id) + ": " + e.what());
    }
  }
  core.cache.put(scan_id, fp);
  return fp;
}

std::optional<LabelledScan> raw(const Core& core, std::int64_t scan_id) {
  auto db = core.readers.acquire();
  const auto r = db->query("SELECT raw FROM scan_blobs WHERE scan_id = $1", {scan_id});
  if (r.rows() == 0 || r.isNull(0, 0)) return std::nullopt;
  auto scan = blob::toRawScan(r.blob(0, 0));
  if (!scan) throw StorageError(Code::kCorrupt, "scan " + std::to_string(scan_id) + ": raw cloud has a bad length");
  return scan;
}

std::optional<std::int64_t> find(const Core& core, const std::string& map, const std::string& robot,
                                 const std::string& session, std::int64_t seq, SeqMatch match) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  const std::string query =
      "SELECT s.id FROM scans s JOIN robots rb ON rb.id = s.robot_id JOIN sessions x ON x.id = s.session_id"
      " WHERE s.map_id = $1 AND rb.name = $2 AND x.name = $3 AND " +
      std::string(match == SeqMatch::kExact ? "s.seq = $4" : "s.seq < $4 ORDER BY s.seq DESC LIMIT 1");
  const auto r = db->query(query.c_str(), {map_id, robot, session, seq});
  if (r.rows() == 0) return std::nullopt;
  return r.i64(0, 0);
}

namespace {

// Deletes the scans of one session or robot (`owner` is the scans' column that `id` matches) with their blobs,
// loops, optimised poses and session frames, then the session or robot rows, in `tx`.
std::int64_t deleteScans(Core& core, WriteTx& tx, MapState& m, const char* owner, std::int64_t id, Change kind) {
  const auto& db = tx.conn();
  const std::string scans = std::string("SELECT id FROM scans WHERE map_id = $1 AND ") + owner + " = $2";
  const auto removed = db.query(("SELECT count(*) FROM (" + scans + ") q").c_str(), {m.id, id}).i64(0, 0);
  db.query(("UPDATE maps SET bytes = greatest(0, bytes - (SELECT coalesce(sum(s.fingerprint_bytes +"
            " octet_length(s.descriptor) + coalesce(octet_length(b.raw), 0)), 0) FROM scans s JOIN scan_blobs b"
            " ON b.scan_id = s.id WHERE s.id IN (" +
            scans + "))) WHERE id = $1")
               .c_str(),
           {m.id, id});
  for (const auto& sql : {"DELETE FROM scan_blobs WHERE scan_id IN (" + scans + ")",
                          "DELETE FROM loops WHERE query_scan IN (" + scans + ") OR candidate_scan IN (" + scans + ")",
                          "DELETE FROM optimised_poses WHERE scan_id IN (" + scans + ")"})
    db.query(sql.c_str(), {m.id, id});
  const bool session = kind == Change::kSessionDeleted;
  const std::string sessions = session ? "SELECT $1::bigint" : "SELECT id FROM sessions WHERE robot_id = $1";
  db.query(("DELETE FROM session_frames WHERE session_id IN (" + sessions + ")").c_str(), {id});
  db.query(("DELETE FROM scans WHERE map_id = $1 AND " + std::string(owner) + " = $2").c_str(), {m.id, id});
  db.query(session ? "DELETE FROM sessions WHERE id = $1" : "DELETE FROM sessions WHERE robot_id = $1", {id});
  if (!session) db.query("DELETE FROM robots WHERE id = $1", {id});
  const auto entry = tx.journal(kind, m.id, id);
  // The journal's own entry, applied here as other processes apply it.
  tx.commit(entry, [&] {
    const auto ids =
        m.index->liveIds([&](const IndexEntry& e) { return session ? e.session_id == id : e.robot_id == id; });
    m.index->remove(ids);
    m.deletions += 1;
    for (const auto sid : ids) core.cache.erase(sid);
    if (session) {
      std::erase_if(m.sessions, [&](const auto& s) { return s.second == id; });
    } else {
      std::erase_if(m.sessions, [&](const auto& s) { return s.first.first == id; });
      std::erase_if(m.robots, [&](const auto& r) { return r.second == id; });
    }
  });
  return removed;
}

}  // namespace

std::int64_t deleteSession(Core& core, const std::string& map, const std::string& robot, const std::string& session) {
  WriteTx tx(core);  // first: the names are looked up in the caught-up catalogue
  MapState* m;
  std::int64_t session_id;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(map);
    session_id = m->requireSession(robot, session);
  }
  return deleteScans(core, tx, *m, "session_id", session_id, Change::kSessionDeleted);
}

std::int64_t deleteRobot(Core& core, const std::string& map, const std::string& robot) {
  WriteTx tx(core);
  MapState* m;
  std::int64_t robot_id;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(map);
    robot_id = m->requireRobot(robot);
  }
  return deleteScans(core, tx, *m, "robot_id", robot_id, Change::kRobotDeleted);
}

std::int64_t deleteMap(Core& core, const std::string& map) {
  WriteTx tx(core);
  MapState* m;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(map);
  }
  const auto& db = tx.conn();
  const auto removed = db.query("SELECT count(*) FROM scans WHERE map_id = $1", {m->id}).i64(0, 0);
  static constexpr std::array<const char*, 8> kRows = {
      "DELETE FROM scan_blobs WHERE scan_id IN (SELECT id FROM scans WHERE map_id = $1)",
      "DELETE FROM loops WHERE map_id = $1",
      "DELETE FROM optimised_poses WHERE scan_id IN (SELECT id FROM scans WHERE map_id = $1)",
      "DELETE FROM session_frames WHERE session_id IN"
      " (SELECT x.id FROM sessions x JOIN robots r ON r.id = x.robot_id WHERE r.map_id = $1)",
      "DELETE FROM scans WHERE map_id = $1",
      "DELETE FROM sessions WHERE robot_id IN (SELECT id FROM robots WHERE map_id = $1)",
      "DELETE FROM robots WHERE map_id = $1",
      "DELETE FROM maps WHERE id = $1"};
  for (const char* sql : kRows) db.query(sql, {m->id});
  const auto entry = tx.journal(Change::kMapDeleted, m->id, m->id);
  tx.commit(entry, [&] {
    for (const auto id : m->index->liveIds([](const IndexEntry&) { return true; })) core.cache.erase(id);
    core.catalogue.remove(map);  // m dangles from here
  });
  return removed;
}

}  // namespace sglc::storage::pg::scans
