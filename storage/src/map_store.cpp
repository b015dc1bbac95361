// The SQLite map store: the catalogue operations here, the rest forwarded to the part that owns it (scans and
// blobs, descriptor indexes, pose-graph tables, administration); store_core.hpp has what they share.
#include "sglc/storage/map_store.hpp"

#include <algorithm>
#include <chrono>
#include <mutex>
#include <shared_mutex>

#include "admin.hpp"
#include "map_index.hpp"
#include "map_settings.hpp"
#include "pg_store.hpp"
#include "places_table.hpp"
#include "pose_graph_tables.hpp"
#include "postgres.hpp"
#include "scan_table.hpp"
#include "store_core.hpp"
#include "validate.hpp"

namespace sglc::storage {

double nowSeconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

StoreCore::StoreCore(const StoreOptions& o)
    : options(o),
      db(openDatabase(o)),
      readers(o.path, o.busy_timeout_ms),
      cache(static_cast<std::size_t>(std::max(0.0, o.cache_mb) * 1024 * 1024)) {}

std::int64_t StoreCore::mapId(const std::string& map) const {
  std::shared_lock lock(state_mutex);
  return catalogue.map(map).id;
}

namespace {

using Code = StorageError::Code;

class SqliteMapStore final : public MapStore {
 public:
  explicit SqliteMapStore(const StoreOptions& options) : core_(options) {
    std::unique_lock lock(core_.state_mutex);
    core_.catalogue.load(core_.writer(), options.index);
    for (auto& [name, m] : core_.catalogue.maps()) map_index::load(core_, m);
  }

  ~SqliteMapStore() override {
    try {
      if (core_.options.snapshot_index) snapshot();
    } catch (const std::exception&) {
      // A missing snapshot only costs a rebuild on the next open.
    }
  }

  // ---- Catalogue
  MapInfo createMap(const std::string& name, int dim) override;
  std::vector<MapInfo> listMaps() const override;
  std::optional<MapInfo> findMap(const std::string& name) const override;
  std::vector<RobotInfo> listRobots(const std::string& map) const override;
  std::vector<SessionInfo> listSessions(const std::string& map, const std::string& robot) const override;
  std::optional<FingerprintSettings> mapSettings(const std::string& map) const override {
    return map_settings::read(core_, map);
  }
  std::vector<std::string> recordSettings(const std::string& map) override {
    return map_settings::recordMissing(core_, map);
  }

  // ---- Scans and blobs
  std::int64_t addScan(const NewScan& scan) override { return scan_table::add(core_, scan); }
  std::optional<ScanInfo> scanInfo(std::int64_t scan_id) const override { return scan_table::info(core_, scan_id); }
  std::shared_ptr<const Fingerprint> fingerprint(std::int64_t scan_id) const override {
    return scan_table::fingerprint(core_, scan_id);
  }
  std::shared_ptr<const ViewContext> viewContext(std::int64_t scan_id, const ViewSearchConfig& config) const override {
    return core_.cache.views.get(scan_id, config, [&] { return fingerprint(scan_id); });
  }
  std::optional<LabelledScan> rawScan(std::int64_t scan_id) const override { return scan_table::raw(core_, scan_id); }
  std::optional<std::int64_t> findScan(const std::string& map, const std::string& robot, const std::string& session,
                                       std::int64_t seq) const override {
    return scan_table::find(core_, map, robot, session, seq);
  }
  std::optional<std::int64_t> previousScan(const std::string& map, const std::string& robot, const std::string& session,
                                           std::int64_t seq) const override {
    return scan_table::find(core_, map, robot, session, seq, scan_table::SeqMatch::kLatestBefore);
  }
  std::int64_t deleteSession(const std::string& map, const std::string& robot, const std::string& session) override {
    return scan_table::deleteSession(core_, map, robot, session);
  }
  std::int64_t deleteRobot(const std::string& map, const std::string& robot) override {
    return scan_table::deleteRobot(core_, map, robot);
  }
  std::int64_t deleteMap(const std::string& map) override { return scan_table::deleteMap(core_, map); }

  // ---- Descriptor indexes
  std::vector<SearchHit> search(const SearchRequest& request) const override {
    return map_index::search(core_, request);
  }
  void snapshot() override { map_index::snapshot(core_); }

  // ---- Administration
  void backup(const std::string& dest) const override { admin::backup(core_, dest); }
  std::string integrityCheck() const override { return admin::integrityCheck(core_); }
  Stats stats(const std::string& map) const override { return admin::stats(core_, map); }

  // ---- Pose graph
  std::int64_t addLoop(const std::string& map, const LoopRecord& loop) override {
    return pose_graph_tables::addLoop(core_, map, loop);
  }
  std::vector<LoopRecord> loops(const std::string& map, std::int64_t after_id, std::int64_t limit) const override {
    return pose_graph_tables::loops(core_, map, after_id, limit);
  }
  std::vector<GraphNodeRecord> graphNodes(const std::string& map, std::int64_t after_scan) const override {
    return pose_graph_tables::nodes(core_, map, after_scan);
  }
  std::int64_t saveOptimised(const std::string& map, std::int64_t map_id, const std::vector<OptimisedPose>& poses,
                             const std::vector<SessionFrame>& frames, std::int64_t through_loop) override {
    return pose_graph_tables::saveOptimised(core_, map, map_id, poses, frames, through_loop);
  }
  std::vector<OptimisedPose> optimisedPoses(const std::string& map, const std::string& robot,
                                            const std::string& session, std::int64_t after_scan,
                                            std::int64_t limit) const override {
    return pose_graph_tables::optimisedPoses(core_, map, robot, session, after_scan, limit);
  }
  std::vector<SessionFrame> sessionFrames(const std::string& map) const override {
    return pose_graph_tables::sessionFrames(core_, map);
  }
  std::int64_t graphVersion(const std::string& map) const override {
    return pose_graph_tables::graphVersion(core_, map);
  }
  std::int64_t optimisedThroughLoop(const std::string& map) const override {
    return pose_graph_tables::optimisedThroughLoop(core_, map);
  }

  // ---- Places (lifelong maps)
  void setPlaces(const std::string& map, const std::vector<PlaceRecord>& records) override {
    places_table::set(core_, map, records);
  }
  std::vector<PlaceRecord> places(const std::string& map) const override { return places_table::all(core_, map); }
  std::optional<PlaceRecord> placeOf(std::int64_t scan_id) const override { return places_table::of(core_, scan_id); }
  std::int64_t placeVersions(const std::string& map, std::int64_t place_id) const override {
    return places_table::versions(core_, map, place_id);
  }
  Retired retireScans(const std::string& map, const std::vector<std::int64_t>& scans,
                      const std::vector<LoopRecord>& new_loops) override {
    return places_table::retire(core_, map, scans, new_loops);
  }

 private:
  StoreCore core_;
};

MapInfo SqliteMapStore::createMap(const std::string& name, int dim) {
  validate::newMap(name, dim);
  std::lock_guard write(core_.write_mutex);
  {
    std::shared_lock lock(core_.state_mutex);
    if (const auto* m = core_.catalogue.find(name)) {
      if (m->dim != dim)
        throw StorageError(Code::kAlreadyExists,
                           "map '" + name + "' exists with descriptor dimension " + std::to_string(m->dim));
      return m->info();
    }
  }
  const auto& db = core_.writer();
  sql::Transaction tx(db);
  // Ids are never reused (as AUTOINCREMENT would, which the table was made without): a map deleted and created
  // again under its name is a new map, so work begun for the old one (a pose-graph solve) cannot land in it.
  sql::Stmt(db,
            "INSERT INTO maps(id, name, descriptor_dim, created_at) VALUES(1 + max("
            "coalesce((SELECT max(id) FROM maps), 0),"
            "coalesce((SELECT CAST(value AS INTEGER) FROM meta WHERE key = 'last_map_id'), 0)), ?, ?, ?)")
      .bind(1, name)
      .bind(2, static_cast<std::int64_t>(dim))
      .bind(3, nowSeconds())
      .run();
  MapState state;
  state.id = sqlite3_last_insert_rowid(db.get());
  sql::Stmt(db, "INSERT OR REPLACE INTO meta(key, value) VALUES('last_map_id', ?)")
      .bind(1, std::to_string(state.id))
      .run();
  map_settings::write(db, state.id, core_.options.settings);
  state.name = name;
  state.dim = dim;
  state.index = std::make_unique<DescriptorIndex>(dim, core_.options.index);
  std::unique_lock lock(core_.state_mutex);
  tx.commit();
  return core_.catalogue.add(std::move(state)).info();
}

std::vector<MapInfo> SqliteMapStore::listMaps() const {
  std::shared_lock lock(core_.state_mutex);
  return core_.catalogue.infos();
}

std::optional<MapInfo> SqliteMapStore::findMap(const std::string& name) const {
  std::shared_lock lock(core_.state_mutex);
  return core_.catalogue.info(name);
}

std::vector<RobotInfo> SqliteMapStore::listRobots(const std::string& map) const {
  std::shared_lock lock(core_.state_mutex);
  const MapState& m = core_.catalogue.map(map);
  auto reader = core_.readers.acquire();
  sql::Stmt st(*reader,
               "SELECT r.name, (SELECT count(*) FROM scans s WHERE s.robot_id = r.id),"
               " (SELECT count(*) FROM sessions x WHERE x.robot_id = r.id)"
               " FROM robots r WHERE r.map_id = ? ORDER BY r.name");
  st.bind(1, m.id);
  std::vector<RobotInfo> out;
  while (st.step()) out.push_back({st.text(0), st.i64(1), st.i64(2)});
  return out;
}

std::vector<SessionInfo> SqliteMapStore::listSessions(const std::string& map, const std::string& robot) const {
  std::shared_lock lock(core_.state_mutex);
  const MapState& m = core_.catalogue.map(map);
  if (!robot.empty()) m.requireRobot(robot);
  auto reader = core_.readers.acquire();
  sql::Stmt st(*reader,
               "SELECT r.name, x.name, count(s.id), coalesce(min(s.seq), 0), coalesce(max(s.seq), 0)"
               " FROM sessions x JOIN robots r ON r.id = x.robot_id LEFT JOIN scans s ON s.session_id = x.id"
               " WHERE r.map_id = ? AND (? = '' OR r.name = ?) GROUP BY x.id ORDER BY r.name, x.name");
  st.bind(1, m.id).bind(2, robot).bind(3, robot);
  std::vector<SessionInfo> out;
  while (st.step()) out.push_back({st.text(0), st.text(1), st.i64(2), st.i64(3), st.i64(4)});
  return out;
}

}  // namespace

bool isPostgresUrl(const std::string& path) { return pg::isUrl(path); }
std::string printableLocation(const std::string& path) { return pg::isUrl(path) ? pg::redacted(path) : path; }

std::unique_ptr<MapStore> MapStore::open(const StoreOptions& options) {
  if (pg::isUrl(options.path)) return pg::open(options);
  return std::make_unique<SqliteMapStore>(options);
}

}  // namespace sglc::storage
