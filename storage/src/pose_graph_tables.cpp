#include "pose_graph_tables.hpp"

#include <cmath>

#include "blob_codec.hpp"
#include "validate.hpp"

namespace sglc::storage::pose_graph_tables {
namespace {

using Code = StorageError::Code;

// An integer column of the map's row in `maps` (one of the fixed columns below, never user input).
std::int64_t mapRowValue(const StoreCore& core, const std::string& map, const char* query) {
  const auto map_id = core.mapId(map);
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader, query);
  st.bind(1, map_id);
  return st.step() ? st.i64(0) : 0;
}

}  // namespace

std::int64_t addLoop(StoreCore& core, const std::string& map, const LoopRecord& loop) {
  validate::loop(loop);
  std::lock_guard write(core.write_mutex);
  const auto map_id = core.mapId(map);
  const auto& db = core.writer();
  sql::Transaction tx(db);
  for (const auto scan : {loop.query_scan, loop.candidate_scan}) {
    sql::Stmt st(db, "SELECT 1 FROM scans WHERE id = ? AND map_id = ?");
    st.bind(1, scan).bind(2, map_id);
    if (!st.step()) throw StorageError(Code::kNotFound, "map '" + map + "' has no scan " + std::to_string(scan));
  }
  const auto t = blob::fromPose(loop.T);
  sql::Stmt(db, "DELETE FROM loops WHERE query_scan = ? AND candidate_scan = ?")
      .bind(1, loop.query_scan)
      .bind(2, loop.candidate_scan)
      .run();
  sql::Stmt st(db,
               "INSERT INTO loops(map_id, query_scan, candidate_scan, t, score, inliers, fitness, rmse, created_at,"
               " information, probability) VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)");
  st.bind(1, map_id).bind(2, loop.query_scan).bind(3, loop.candidate_scan).bindBlob(4, t).bind(5, loop.score);
  st.bind(6, static_cast<std::int64_t>(loop.inliers)).bind(7, loop.fitness).bind(8, loop.rmse).bind(9, nowSeconds());
  const auto info = loop.information ? blob::fromInformation(*loop.information) : std::vector<std::uint8_t>{};
  if (loop.information)
    st.bindBlob(10, info);
  else
    st.bindNull(10);
  if (loop.probability)
    st.bind(11, *loop.probability);
  else
    st.bindNull(11);
  st.run();
  const auto id = sqlite3_last_insert_rowid(db.get());
  tx.commit();
  return id;
}

std::vector<LoopRecord> loops(const StoreCore& core, const std::string& map, std::int64_t after_id,
                              std::int64_t limit) {
  const auto map_id = core.mapId(map);
  auto reader = core.readers.acquire();
  sql::Stmt st(
      *reader,
      "SELECT id, query_scan, candidate_scan, t, score, inliers, fitness, rmse, information, probability FROM loops"
      " WHERE map_id = ? AND id > ? ORDER BY id LIMIT ?");
  st.bind(1, map_id).bind(2, after_id).bind(3, limit > 0 ? limit : std::int64_t{-1});  // -1: no limit
  std::vector<LoopRecord> out;
  while (st.step()) {
    LoopRecord r;
    r.id = st.i64(0);
    r.query_scan = st.i64(1);
    r.candidate_scan = st.i64(2);
    r.T = blob::requirePose(st.blob(3), "loop " + std::to_string(r.id), "transform");
    r.score = st.f64(4);
    r.inliers = static_cast<int>(st.i64(5));
    r.fitness = st.f64(6);
    r.rmse = st.f64(7);
    if (!st.isNull(8)) {
      r.information = blob::toInformation(st.blob(8));
      if (!r.information)
        throw StorageError(Code::kCorrupt, "loop " + std::to_string(r.id) + " has a damaged information matrix");
    }
    if (!st.isNull(9)) r.probability = st.f64(9);
    out.push_back(r);
  }
  return out;
}

std::vector<GraphNodeRecord> nodes(const StoreCore& core, const std::string& map, std::int64_t after_scan) {
  const auto map_id = core.mapId(map);
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader,
               "SELECT s.id, s.session_id, r.name, e.name, s.seq, s.stamp, s.pose FROM scans s"
               " JOIN sessions e ON e.id = s.session_id JOIN robots r ON r.id = s.robot_id"
               " WHERE s.map_id = ? AND s.id > ? ORDER BY s.id");
  st.bind(1, map_id).bind(2, after_scan);
  std::vector<GraphNodeRecord> out;
  while (st.step()) {
    GraphNodeRecord n;
    n.scan_id = st.i64(0);
    n.session_id = st.i64(1);
    n.robot = st.text(2);
    n.session = st.text(3);
    n.seq = st.i64(4);
    if (!st.isNull(5)) n.stamp = st.f64(5);
    if (!st.isNull(6)) n.odometry_pose = blob::toPose(st.blob(6));
    out.push_back(std::move(n));
  }
  return out;
}

std::int64_t saveOptimised(StoreCore& core, const std::string& map, std::int64_t expected_map_id,
                           const std::vector<OptimisedPose>& poses, const std::vector<SessionFrame>& frames,
                           std::int64_t through_loop) {
  validate::optimised(poses, frames);
  std::lock_guard write(core.write_mutex);
  const auto map_id = core.mapId(map);
  if (map_id != expected_map_id)  // a solve of a deleted map whose name was created again: not this map's poses
    throw StorageError(Code::kNotFound, "map '" + map + "' was deleted while its pose graph was being solved");
  const auto& db = core.writer();
  sql::Transaction tx(db);
  {
    sql::Stmt st(db,
                 "INSERT OR REPLACE INTO optimised_poses(scan_id, pose)"
                 " SELECT ?1, ?2 WHERE EXISTS(SELECT 1 FROM scans WHERE id = ?1 AND map_id = ?3)");
    for (const auto& p : poses) {
      const auto blob = blob::fromPose(p.pose);
      st.bind(1, p.scan_id).bindBlob(2, blob).bind(3, map_id);
      st.run();
      st.reset();
    }
  }
  {
    sql::Stmt st(db,
                 "INSERT OR REPLACE INTO session_frames(session_id, t, connected)"
                 " SELECT ?1, ?2, ?3 WHERE EXISTS(SELECT 1 FROM sessions e JOIN robots r ON r.id = e.robot_id"
                 " WHERE e.id = ?1 AND r.map_id = ?4)");
    for (const auto& f : frames) {
      const auto blob = blob::fromPose(f.T_map_session);
      st.bind(1, f.session_id).bindBlob(2, blob).bind(3, static_cast<std::int64_t>(f.connected)).bind(4, map_id);
      st.run();
      st.reset();
    }
  }
  sql::Stmt(db, "UPDATE maps SET graph_version = graph_version + 1, graph_loop = ?2 WHERE id = ?1")
      .bind(1, map_id)
      .bind(2, through_loop)
      .run();
  sql::Stmt v(db, "SELECT graph_version FROM maps WHERE id = ?");
  v.bind(1, map_id);
  const std::int64_t version = v.step() ? v.i64(0) : 0;
  v.reset();
  tx.commit();
  return version;
}

std::vector<OptimisedPose> optimisedPoses(const StoreCore& core, const std::string& map, const std::string& robot,
                                          const std::string& session, std::int64_t after_scan, std::int64_t limit) {
  const auto map_id = core.mapId(map);
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader,
               "SELECT o.scan_id, o.pose FROM optimised_poses o JOIN scans s ON s.id = o.scan_id"
               " JOIN sessions e ON e.id = s.session_id JOIN robots r ON r.id = s.robot_id"
               " WHERE s.map_id = ?1 AND o.scan_id > ?2 AND (?3 = '' OR r.name = ?3) AND (?4 = '' OR e.name = ?4)"
               " ORDER BY o.scan_id LIMIT ?5");
  st.bind(1, map_id).bind(2, after_scan).bind(3, robot).bind(4, session).bind(5, limit);
  std::vector<OptimisedPose> out;
  while (st.step()) {
    out.push_back({st.i64(0), blob::requirePose(st.blob(1), "scan " + std::to_string(st.i64(0)), "optimised pose")});
  }
  return out;
}

std::vector<SessionFrame> sessionFrames(const StoreCore& core, const std::string& map) {
  const auto map_id = core.mapId(map);
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader,
               "SELECT f.session_id, r.name, e.name, f.t, f.connected FROM session_frames f"
               " JOIN sessions e ON e.id = f.session_id JOIN robots r ON r.id = e.robot_id"
               " WHERE r.map_id = ? ORDER BY f.session_id");
  st.bind(1, map_id);
  std::vector<SessionFrame> out;
  while (st.step()) {
    SessionFrame f;
    f.session_id = st.i64(0);
    f.robot = st.text(1);
    f.session = st.text(2);
    f.T_map_session = blob::requirePose(st.blob(3), "session " + std::to_string(f.session_id), "frame");
    f.connected = st.i64(4) != 0;
    out.push_back(std::move(f));
  }
  return out;
}
std::int64_t graphVersion(const StoreCore& core, const std::string& map) {
  return mapRowValue(core, map, "SELECT graph_version FROM maps WHERE id = ?");
}

std::int64_t optimisedThroughLoop(const StoreCore& core, const std::string& map) {
  return mapRowValue(core, map, "SELECT graph_loop FROM maps WHERE id = ?");
}

}  // namespace sglc::storage::pose_graph_tables
