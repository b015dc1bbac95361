// Deleting a session's, a robot's or a whole map's scans with everything that hangs on them (blobs, loops,
// optimised poses, session frames, then the session, robot and map rows), in one transaction, and out of the
// index and the cache.
#include <array>
#include <unordered_set>
#include <vector>

#include "map_index.hpp"
#include "scan_table.hpp"

namespace sglc::storage::scan_table {
namespace {

using Code = StorageError::Code;

// The statements of one kind of deletion, all bound to ?1 = the map's id and ?2 = the session's or robot's id:
// first the ids of the scans removed, then the rows in dependency order.
struct Deletion {
  const char* scan_ids;
  std::array<const char*, 8> rows;
};

constexpr Deletion kSession = {
    "SELECT id FROM scans WHERE map_id = ?1 AND session_id = ?2",
    {"DELETE FROM scan_blobs WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1 AND session_id = ?2)",
     "DELETE FROM loops WHERE query_scan IN (SELECT id FROM scans WHERE map_id = ?1 AND session_id = ?2) OR"
     " candidate_scan IN (SELECT id FROM scans WHERE map_id = ?1 AND session_id = ?2)",
     "DELETE FROM optimised_poses WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1 AND session_id = ?2)",
     "DELETE FROM session_frames WHERE session_id IN"
     " (SELECT session_id FROM scans WHERE map_id = ?1 AND session_id = ?2)",
     "DELETE FROM places WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1 AND session_id = ?2)",
     "DELETE FROM scans WHERE map_id = ?1 AND session_id = ?2", "DELETE FROM sessions WHERE id = ?2", nullptr}};

constexpr Deletion kRobot = {
    "SELECT id FROM scans WHERE map_id = ?1 AND robot_id = ?2",
    {"DELETE FROM scan_blobs WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1 AND robot_id = ?2)",
     "DELETE FROM loops WHERE query_scan IN (SELECT id FROM scans WHERE map_id = ?1 AND robot_id = ?2) OR"
     " candidate_scan IN (SELECT id FROM scans WHERE map_id = ?1 AND robot_id = ?2)",
     "DELETE FROM optimised_poses WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1 AND robot_id = ?2)",
     "DELETE FROM session_frames WHERE session_id IN"
     " (SELECT session_id FROM scans WHERE map_id = ?1 AND robot_id = ?2)",
     "DELETE FROM places WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1 AND robot_id = ?2)",
     "DELETE FROM scans WHERE map_id = ?1 AND robot_id = ?2", "DELETE FROM sessions WHERE robot_id = ?2",
     "DELETE FROM robots WHERE id = ?2"}};

// Runs `deletion` for `id` (the caller holds the write lock); `update` then fixes the catalogue under the
// exclusive state lock, with the commit. Returns the number of scans removed from the index.
template <typename UpdateCatalogue>
std::int64_t deleteScans(StoreCore& core, MapState& m, const Deletion& deletion, std::int64_t id,
                         UpdateCatalogue update) {
  const auto& db = core.writer();
  sql::Transaction tx(db);
  std::unordered_set<std::int64_t> ids;
  {
    sql::Stmt st(db, deletion.scan_ids);
    st.bind(1, m.id).bind(2, id);
    while (st.step()) ids.insert(st.i64(0));
  }
  for (const char* text : deletion.rows)
    if (text) sql::Stmt(db, text).bind(1, m.id).bind(2, id).run();
  sql::Stmt(db, "UPDATE maps SET generation = generation + 1 WHERE id = ?").bind(1, m.id).run();
  std::unique_lock lock(core.state_mutex);
  tx.commit();
  m.generation += 1;
  m.deletions += 1;
  const auto removed = m.index->remove(ids);
  update();
  for (auto sid : ids) core.cache.erase(sid);
  return removed;
}

}  // namespace

std::int64_t deleteSession(StoreCore& core, const std::string& map, const std::string& robot,
                           const std::string& session) {
  std::lock_guard write(core.write_mutex);
  MapState* m;
  std::int64_t session_id;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(map);
    session_id = m->requireSession(robot, session);
  }
  return deleteScans(core, *m, kSession, session_id, [&] {
    for (auto it = m->sessions.begin(); it != m->sessions.end();)
      it = it->second == session_id ? m->sessions.erase(it) : std::next(it);
  });
}

std::int64_t deleteRobot(StoreCore& core, const std::string& map, const std::string& robot) {
  std::lock_guard write(core.write_mutex);
  MapState* m;
  std::int64_t robot_id;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(map);
    robot_id = m->requireRobot(robot);
  }
  return deleteScans(core, *m, kRobot, robot_id, [&] {
    m->robots.erase(robot);
    for (auto it = m->sessions.begin(); it != m->sessions.end();)
      it = it->first.first == robot_id ? m->sessions.erase(it) : std::next(it);
  });
}

std::int64_t deleteMap(StoreCore& core, const std::string& map) {
  std::lock_guard write(core.write_mutex);
  MapState* m;
  {
    std::shared_lock lock(core.state_mutex);
    m = &core.catalogue.map(map);
  }
  const auto& db = core.writer();
  sql::Transaction tx(db);
  std::vector<std::int64_t> ids;
  {
    sql::Stmt st(db, "SELECT id FROM scans WHERE map_id = ?1");
    st.bind(1, m->id);
    while (st.step()) ids.push_back(st.i64(0));
  }
  static constexpr std::array<const char*, 9> kRows = {
      "DELETE FROM scan_blobs WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1)",
      "DELETE FROM loops WHERE map_id = ?1",
      "DELETE FROM optimised_poses WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1)",
      "DELETE FROM session_frames WHERE session_id IN"
      " (SELECT x.id FROM sessions x JOIN robots r ON r.id = x.robot_id WHERE r.map_id = ?1)",
      "DELETE FROM places WHERE map_id = ?1",
      "DELETE FROM scans WHERE map_id = ?1",
      "DELETE FROM sessions WHERE robot_id IN (SELECT id FROM robots WHERE map_id = ?1)",
      "DELETE FROM robots WHERE map_id = ?1",
      "DELETE FROM maps WHERE id = ?1"};
  for (const char* text : kRows) sql::Stmt(db, text).bind(1, m->id).run();
  const auto map_id = m->id;
  {
    std::unique_lock lock(core.state_mutex);
    tx.commit();
    core.catalogue.remove(map);  // m dangles from here
  }
  for (auto sid : ids) core.cache.erase(sid);
  // A map created later may get the same id: its index must not load this map's snapshot.
  map_index::removeSnapshot(core, map_id);
  return static_cast<std::int64_t>(ids.size());
}

}  // namespace sglc::storage::scan_table
