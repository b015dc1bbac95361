#include "map_index.hpp"

#include <cmath>
#include <filesystem>

namespace sglc::storage::map_index {
namespace {

namespace fs = std::filesystem;
using Code = StorageError::Code;

std::string snapshotDir(const StoreCore& core) { return core.options.path + ".index"; }
std::string snapshotPath(const StoreCore& core, std::int64_t map_id) {
  return snapshotDir(core) + "/map-" + std::to_string(map_id) + "-" + core.db.token + ".sgix";
}

void rebuild(const StoreCore& core, MapState& m) {
  std::vector<IndexEntry> entries;
  std::vector<float> vectors;
  sql::Stmt st(core.writer(),
               "SELECT id, robot_id, session_id, seq, stamp, descriptor FROM scans WHERE map_id = ? ORDER BY id");
  st.bind(1, m.id);
  while (st.step()) {
    const auto blob = st.blob(5);
    if (blob.size() != static_cast<std::size_t>(m.dim) * sizeof(float))
      throw StorageError(Code::kCorrupt, core.options.path + ": scan " + std::to_string(st.i64(0)) +
                                             " has a descriptor of the wrong length");
    entries.push_back({st.i64(0), st.i64(1), st.i64(2), st.i64(3), st.isNull(4) ? std::nan("") : st.f64(4), false});
    const auto* f = reinterpret_cast<const float*>(blob.data());
    vectors.insert(vectors.end(), f, f + m.dim);
  }
  m.index->build(std::move(entries), vectors);
}

// The request's names as the index's ids (a name the map does not have matches nothing).
SearchFilter filterOf(const MapState& m, const SearchRequest& req) {
  SearchFilter filter;
  filter.self_stamp = req.self_stamp ? *req.self_stamp : std::nan("");
  filter.exclude_seconds = req.exclude_seconds;
  filter.exclude_recent = req.exclude_recent;
  filter.self_seq = req.self_seq;
  for (const auto& r : req.robots) filter.robots.insert(m.robotId(r));
  for (const auto& r : req.exclude_robots) filter.exclude_robots.insert(m.robotId(r));
  for (const auto& s : req.sessions) {
    const auto slash = s.find('/');
    if (slash == std::string::npos)
      throw StorageError(Code::kInvalidArgument, "session filter '" + s + "' must be 'robot/session'");
    filter.sessions.insert(m.sessionId(m.robotId(s.substr(0, slash)), s.substr(slash + 1)));
  }
  for (const auto& [robot, session] : req.session_refs) filter.sessions.insert(m.sessionId(m.robotId(robot), session));
  filter.exclude_scans.insert(req.exclude_scan_ids.begin(), req.exclude_scan_ids.end());
  if (!req.self_robot.empty()) {
    filter.self_robot = m.robotId(req.self_robot);
    filter.self_session = m.sessionId(filter.self_robot, req.self_session);
  }
  return filter;
}

}  // namespace

void load(StoreCore& core, MapState& m) {
  if (core.options.snapshot_index && m.index->load(snapshotPath(core, m.id), m.generation)) return;
  rebuild(core, m);
}

std::vector<SearchHit> searchMap(const MapState& m, const SearchRequest& req) {
  if (static_cast<int>(req.descriptor.size()) != m.dim)
    throw StorageError(Code::kInvalidArgument, "query descriptor has " + std::to_string(req.descriptor.size()) +
                                                   " values, map '" + req.map + "' needs " + std::to_string(m.dim));
  for (float v : req.descriptor)
    if (!std::isfinite(v)) throw StorageError(Code::kInvalidArgument, "query descriptor is not finite");
  if (req.k <= 0 || req.k > 10000) throw StorageError(Code::kInvalidArgument, "k must be 1..10000");
  return m.index->search(req.descriptor.data(), req.k, filterOf(m, req));
}

std::vector<SearchHit> search(const StoreCore& core, const SearchRequest& req) {
  std::shared_lock lock(core.state_mutex);
  return searchMap(core.catalogue.map(req.map), req);
}

void snapshot(StoreCore& core) {
  std::lock_guard write(core.write_mutex);
  std::shared_lock lock(core.state_mutex);
  std::error_code ec;
  fs::create_directories(snapshotDir(core), ec);
  if (ec) throw StorageError(Code::kIo, snapshotDir(core) + ": " + ec.message());
  for (const auto& [name, m] : core.catalogue.maps()) {
    const auto path = snapshotPath(core, m.id);
    if (m.index->hasTombstones()) {
      fs::remove(path, ec);  // the next open rebuilds without the deleted scans
      continue;
    }
    m.index->save(path, m.generation);
  }
}

void removeSnapshot(const StoreCore& core, std::int64_t map_id) {
  std::error_code ec;
  fs::remove(snapshotPath(core, map_id), ec);
}

}  // namespace sglc::storage::map_index
