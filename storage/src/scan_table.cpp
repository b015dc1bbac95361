#include "scan_table.hpp"

#include <cmath>

#include "blob_codec.hpp"
#include "sglc/fingerprint.hpp"
#include "validate.hpp"

namespace sglc::storage::scan_table {
namespace {

using Code = StorageError::Code;

// The scan's robot and session ids, inserting the rows of new ones (inside the caller's transaction; the
// catalogue learns of them after the commit).
struct Owner {
  std::int64_t robot_id = 0, session_id = 0;
  bool new_robot = false, new_session = false;
};
Owner ownerOf(const StoreCore& core, const MapState& m, const NewScan& scan) {
  Owner o;
  const auto& db = core.writer();
  if (auto it = m.robots.find(scan.robot); it != m.robots.end()) {
    o.robot_id = it->second;
  } else {
    sql::Stmt(db, "INSERT INTO robots(map_id, name) VALUES(?, ?)").bind(1, m.id).bind(2, scan.robot).run();
    o.robot_id = sqlite3_last_insert_rowid(db.get());
    o.new_robot = true;
  }
  if (auto it = m.sessions.find({o.robot_id, scan.session}); it != m.sessions.end()) {
    o.session_id = it->second;
  } else {
    sql::Stmt(db, "INSERT INTO sessions(robot_id, name, created_at) VALUES(?, ?, ?)")
        .bind(1, o.robot_id)
        .bind(2, scan.session)
        .bind(3, nowSeconds())
        .run();
    o.session_id = sqlite3_last_insert_rowid(db.get());
    o.new_session = true;
  }
  return o;
}

std::int64_t insertRow(const sql::Db& db, std::int64_t map_id, const Owner& o, const NewScan& scan,
                       std::size_t fingerprint_bytes) {
  const auto& descriptor = scan.fingerprint->descriptor;
  sql::Stmt st(db,
               "INSERT INTO scans(map_id, robot_id, session_id, seq, stamp, pose, descriptor, fingerprint_bytes,"
               " has_raw, created_at) VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?)");
  st.bind(1, map_id).bind(2, o.robot_id).bind(3, o.session_id).bind(4, scan.seq);
  if (scan.stamp)
    st.bind(5, *scan.stamp);
  else
    st.bindNull(5);
  std::vector<std::uint8_t> pose;
  if (scan.odometry_pose) {
    pose = blob::fromPose(*scan.odometry_pose);
    st.bindBlob(6, pose);
  } else {
    st.bindNull(6);
  }
  st.bindBlob(7, {reinterpret_cast<const std::uint8_t*>(descriptor.data()), descriptor.size() * sizeof(float)});
  st.bind(8, static_cast<std::int64_t>(fingerprint_bytes));
  st.bind(9, static_cast<std::int64_t>(scan.raw ? 1 : 0));
  st.bind(10, nowSeconds());
  try {
    st.run();
  } catch (const StorageError& e) {
    if (e.code() == Code::kAlreadyExists)
      throw StorageError(Code::kAlreadyExists, "robot '" + scan.robot + "' session '" + scan.session +
                                                   "' already has a scan with seq " + std::to_string(scan.seq));
    throw;
  }
  return sqlite3_last_insert_rowid(db.get());
}

}  // namespace

std::int64_t add(StoreCore& core, const NewScan& scan) {
  validate::scan(scan);
  const auto& descriptor = scan.fingerprint->descriptor;
  const auto fingerprint = serialize(*scan.fingerprint);
  const auto raw = scan.raw ? blob::fromRawScan(*scan.raw) : std::vector<std::uint8_t>();

  std::lock_guard write(core.write_mutex);  // one writer at a time; readers continue until the commit
  MapState* m;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(scan.map);
  }
  if (static_cast<int>(descriptor.size()) != m->dim)
    throw StorageError(Code::kInvalidArgument, "descriptor has " + std::to_string(descriptor.size()) +
                                                   " values, map '" + scan.map + "' needs " + std::to_string(m->dim));
  const auto& db = core.writer();
  sql::Transaction tx(db);
  const auto owner = ownerOf(core, *m, scan);
  const auto scan_id = insertRow(db, m->id, owner, scan, fingerprint.size());
  {
    sql::Stmt st(db, "INSERT INTO scan_blobs(scan_id, fingerprint, raw) VALUES(?, ?, ?)");
    st.bind(1, scan_id).bindBlob(2, fingerprint);
    if (scan.raw)
      st.bindBlob(3, raw);
    else
      st.bindNull(3);
    st.run();
  }
  sql::Stmt(db, "UPDATE maps SET generation = generation + 1 WHERE id = ?").bind(1, m->id).run();

  IndexEntry entry{scan_id, owner.robot_id, owner.session_id, scan.seq, scan.stamp ? *scan.stamp : std::nan(""), false};
  // The commit and the index update happen under the exclusive lock: no reader sees one without the other.
  std::unique_lock lock(core.state_mutex);
  tx.commit();
  m->generation += 1;
  if (owner.new_robot) m->robots[scan.robot] = owner.robot_id;
  if (owner.new_session) m->sessions[{owner.robot_id, scan.session}] = owner.session_id;
  m->index->add(entry, descriptor.data());
  return scan_id;
}

std::optional<ScanInfo> info(const StoreCore& core, std::int64_t scan_id) {
  std::shared_lock lock(core.state_mutex);
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader,
               "SELECT s.map_id, r.name, x.name, s.seq, s.stamp, s.pose, s.fingerprint_bytes, s.has_raw"
               " FROM scans s JOIN robots r ON r.id = s.robot_id JOIN sessions x ON x.id = s.session_id"
               " WHERE s.id = ?");
  st.bind(1, scan_id);
  if (!st.step()) return std::nullopt;
  ScanInfo info;
  info.id = scan_id;
  info.map = core.catalogue.nameOf(st.i64(0));
  info.robot = st.text(1);
  info.session = st.text(2);
  info.seq = st.i64(3);
  if (!st.isNull(4)) info.stamp = st.f64(4);
  if (!st.isNull(5)) info.odometry_pose = blob::toPose(st.blob(5));
  info.fingerprint_bytes = st.i64(6);
  info.has_raw = st.i64(7) != 0;
  return info;
}

std::shared_ptr<const Fingerprint> fingerprint(const StoreCore& core, std::int64_t scan_id) {
  if (auto hit = core.cache.get(scan_id)) return hit;
  std::shared_ptr<const Fingerprint> fp;
  {
    std::shared_lock lock(core.state_mutex);
    auto reader = core.readers.acquire();
    sql::Stmt st(*reader, "SELECT fingerprint FROM scan_blobs WHERE scan_id = ?");
    st.bind(1, scan_id);
    if (!st.step()) return nullptr;
    try {
      fp = std::make_shared<const Fingerprint>(deserialize(st.blob(0)));
    } catch (const InputError& e) {
      throw StorageError(Code::kCorrupt, "scan " + std::to_string(scan_id) + ": " + e.what());
    }
  }
  core.cache.put(scan_id, fp);
  return fp;
}

std::optional<LabelledScan> raw(const StoreCore& core, std::int64_t scan_id) {
  std::shared_lock lock(core.state_mutex);
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader, "SELECT raw FROM scan_blobs WHERE scan_id = ?");
  st.bind(1, scan_id);
  if (!st.step() || st.isNull(0)) return std::nullopt;
  auto scan = blob::toRawScan(st.blob(0));
  if (!scan) throw StorageError(Code::kCorrupt, "scan " + std::to_string(scan_id) + ": raw cloud has a bad length");
  return scan;
}

std::optional<std::int64_t> find(const StoreCore& core, const std::string& map, const std::string& robot,
                                 const std::string& session, std::int64_t seq, SeqMatch match) {
  std::shared_lock lock(core.state_mutex);
  const MapState& m = core.catalogue.map(map);
  const auto robot_id = m.robotId(robot);
  const auto session_id = robot_id < 0 ? -1 : m.sessionId(robot_id, session);
  if (session_id < 0) return std::nullopt;
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader, match == SeqMatch::kExact
                            ? "SELECT id FROM scans WHERE session_id = ? AND seq = ?"
                            : "SELECT id FROM scans WHERE session_id = ? AND seq < ? ORDER BY seq DESC LIMIT 1");
  st.bind(1, session_id).bind(2, seq);
  if (!st.step()) return std::nullopt;
  return st.i64(0);
}

}  // namespace sglc::storage::scan_table
