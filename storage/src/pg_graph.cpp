// The pose-graph tables in PostgreSQL: verified loops, optimised poses and session frames.
#include "blob_codec.hpp"
#include "pg_parts.hpp"
#include "validate.hpp"

namespace sglc::storage::pg::graph {
namespace {

using Code = StorageError::Code;

using Bytes = std::span<const std::uint8_t>;

void appendHex(std::string& out, const std::vector<std::uint8_t>& bytes) {
  static constexpr char kDigits[] = "0123456789abcdef";
  out += "\\\\x";  // COPY's text format unescapes this to bytea's \x prefix
  for (const auto b : bytes) {
    out += kDigits[b >> 4];
    out += kDigits[b & 15];
  }
}

}  // namespace

std::int64_t addLoop(Core& core, const std::string& map, const LoopRecord& loop) {
  validate::loop(loop);
  WriteTx tx(core);  // loop ids commit in order, as loops(after_id) readers assume
  const auto map_id = core.mapId(map);
  const auto& db = tx.conn();
  for (const auto scan : {loop.query_scan, loop.candidate_scan})
    if (db.query("SELECT 1 FROM scans WHERE id = $1 AND map_id = $2", {scan, map_id}).rows() == 0)
      throw StorageError(Code::kNotFound, "map '" + map + "' has no scan " + std::to_string(scan));
  db.query("DELETE FROM loops WHERE query_scan = $1 AND candidate_scan = $2", {loop.query_scan, loop.candidate_scan});
  const auto t = blob::fromPose(loop.T);
  const auto info = loop.information ? blob::fromInformation(*loop.information) : std::vector<std::uint8_t>{};
  const auto id = db.query(
                        "INSERT INTO loops(map_id, query_scan, candidate_scan, t, score, inliers, fitness, rmse,"
                        " created_at, information, probability) VALUES($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11)"
                        " RETURNING id",
                        {map_id, loop.query_scan, loop.candidate_scan, Bytes(t), loop.score, loop.inliers, loop.fitness,
                         loop.rmse, nowSeconds(), loop.information ? Param(Bytes(info)) : Param(),
                         loop.probability ? Param(*loop.probability) : Param()})
                      .i64(0, 0);
  tx.commit(0, [] {});
  return id;
}

std::vector<LoopRecord> loops(const Core& core, const std::string& map, std::int64_t after_id, std::int64_t limit) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  const auto r = db->query(
      "SELECT id, query_scan, candidate_scan, t, score, inliers, fitness, rmse, information, probability FROM loops"
      " WHERE map_id = $1 AND id > $2 ORDER BY id LIMIT $3",
      {map_id, after_id, limit > 0 ? Param(limit) : Param()});  // LIMIT NULL: no limit
  std::vector<LoopRecord> out;
  for (int i = 0; i < r.rows(); ++i) {
    LoopRecord l;
    l.id = r.i64(i, 0);
    l.query_scan = r.i64(i, 1);
    l.candidate_scan = r.i64(i, 2);
    l.T = blob::requirePose(r.blob(i, 3), "loop " + std::to_string(l.id), "transform");
    l.score = r.f64(i, 4);
    l.inliers = static_cast<int>(r.i64(i, 5));
    l.fitness = r.f64(i, 6);
    l.rmse = r.f64(i, 7);
    if (!r.isNull(i, 8)) {
      l.information = blob::toInformation(r.blob(i, 8));
      if (!l.information)
        throw StorageError(Code::kCorrupt, "loop " + std::to_string(l.id) + " has a damaged information matrix");
    }
    if (!r.isNull(i, 9)) l.probability = r.f64(i, 9);
    out.push_back(l);
  }
  return out;
}

std::vector<GraphNodeRecord> nodes(const Core& core, const std::string& map, std::int64_t after_scan) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  const auto r = db->query(
      "SELECT s.id, s.session_id, rb.name, x.name, s.seq, s.stamp, s.pose FROM scans s"
      " JOIN sessions x ON x.id = s.session_id JOIN robots rb ON rb.id = s.robot_id"
      " WHERE s.map_id = $1 AND s.id > $2 ORDER BY s.id",
      {map_id, after_scan});
  std::vector<GraphNodeRecord> out;
  out.reserve(static_cast<std::size_t>(r.rows()));
  for (int i = 0; i < r.rows(); ++i) {
    GraphNodeRecord n;
    n.scan_id = r.i64(i, 0);
    n.session_id = r.i64(i, 1);
    n.robot = r.text(i, 2);
    n.session = r.text(i, 3);
    n.seq = r.i64(i, 4);
    if (!r.isNull(i, 5)) n.stamp = r.f64(i, 5);
    if (!r.isNull(i, 6)) n.odometry_pose = blob::toPose(r.blob(i, 6));
    out.push_back(std::move(n));
  }
  return out;
}

std::int64_t saveOptimised(Core& core, const std::string& map, std::int64_t expected_map_id,
                           const std::vector<OptimisedPose>& poses, const std::vector<SessionFrame>& frames,
                           std::int64_t through_loop) {
  validate::optimised(poses, frames);
  // Under the write lock: a deletion by another replica is either wholly before (the map or its scans are gone
  // and skipped) or wholly after.
  WriteTx tx(core);
  const auto& db = tx.conn();
  // Checked in the database, not the catalogue, which may lag another replica's deletion.
  if (db.query("SELECT 1 FROM maps WHERE id = $1 AND name = $2", {expected_map_id, map}).rows() == 0)
    throw StorageError(Code::kNotFound, "map '" + map + "' was deleted while its pose graph was being solved");
  // Thousands of poses in one COPY, then one statement that keeps those of scans still in the map.
  db.exec("CREATE TEMP TABLE IF NOT EXISTS sglc_new_poses(scan_id bigint, pose bytea) ON COMMIT DELETE ROWS");
  std::string data;
  data.reserve(poses.size() * 220);
  for (const auto& p : poses) {
    data += std::to_string(p.scan_id) + '\t';
    appendHex(data, blob::fromPose(p.pose));
    data += '\n';
  }
  db.copyIn("COPY sglc_new_poses(scan_id, pose) FROM STDIN", data);
  db.query(
      "INSERT INTO optimised_poses(scan_id, pose) SELECT n.scan_id, n.pose FROM sglc_new_poses n"
      " JOIN scans s ON s.id = n.scan_id AND s.map_id = $1"
      " ON CONFLICT(scan_id) DO UPDATE SET pose = excluded.pose",
      {expected_map_id});
  for (const auto& f : frames) {
    const auto t = blob::fromPose(f.T_map_session);
    db.query(
        "INSERT INTO session_frames(session_id, t, connected) SELECT $1, $2, $3 WHERE EXISTS("
        "SELECT 1 FROM sessions x JOIN robots r ON r.id = x.robot_id WHERE x.id = $1 AND r.map_id = $4)"
        " ON CONFLICT(session_id) DO UPDATE SET t = excluded.t, connected = excluded.connected",
        {f.session_id, Bytes(t), f.connected ? "true" : "false", expected_map_id});
  }
  const auto version = db.query(
                             "UPDATE maps SET graph_version = graph_version + 1, graph_loop = $2 WHERE id = $1"
                             " RETURNING graph_version",
                             {expected_map_id, through_loop})
                           .i64(0, 0);
  tx.commit(0, [] {});
  return version;
}

std::vector<OptimisedPose> optimisedPoses(const Core& core, const std::string& map, const std::string& robot,
                                          const std::string& session, std::int64_t after_scan, std::int64_t limit) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  const auto r = db->query(
      "SELECT o.scan_id, o.pose FROM optimised_poses o JOIN scans s ON s.id = o.scan_id"
      " JOIN sessions x ON x.id = s.session_id JOIN robots rb ON rb.id = s.robot_id"
      " WHERE s.map_id = $1 AND o.scan_id > $2 AND ($3 = '' OR rb.name = $3) AND ($4 = '' OR x.name = $4)"
      " ORDER BY o.scan_id LIMIT $5",
      {map_id, after_scan, robot, session, limit >= 0 ? Param(limit) : Param()});
  std::vector<OptimisedPose> out;
  for (int i = 0; i < r.rows(); ++i) {
    out.push_back(
        {r.i64(i, 0), blob::requirePose(r.blob(i, 1), "scan " + std::to_string(r.i64(i, 0)), "optimised pose")});
  }
  return out;
}

std::vector<SessionFrame> sessionFrames(const Core& core, const std::string& map) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  const auto r = db->query(
      "SELECT f.session_id, rb.name, x.name, f.t, f.connected FROM session_frames f"
      " JOIN sessions x ON x.id = f.session_id JOIN robots rb ON rb.id = x.robot_id"
      " WHERE rb.map_id = $1 ORDER BY f.session_id",
      {map_id});
  std::vector<SessionFrame> out;
  for (int i = 0; i < r.rows(); ++i) {
    SessionFrame f;
    f.session_id = r.i64(i, 0);
    f.robot = r.text(i, 1);
    f.session = r.text(i, 2);
    f.T_map_session = blob::requirePose(r.blob(i, 3), "session " + std::to_string(f.session_id), "frame");
    f.connected = r.boolean(i, 4);
    out.push_back(std::move(f));
  }
  return out;
}

std::int64_t mapValue(const Core& core, const std::string& map, const char* column_query) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  const auto r = db->query(column_query, {map_id});
  return r.rows() ? r.i64(0, 0) : 0;
}

}  // namespace sglc::storage::pg::graph
