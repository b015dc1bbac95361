// The PostgreSQL map store: the catalogue operations here, the rest forwarded to the part that owns it (scans,
// pose-graph tables, administration); pg_core.hpp has what they share and how replicas stay in step.
#include "pg_store.hpp"

#include "map_index.hpp"
#include "pg_parts.hpp"
#include "pg_schema.hpp"
#include "validate.hpp"

namespace sglc::storage::pg {
namespace {

using Code = StorageError::Code;

constexpr int kFollowPollMs = 1000;

// Session settings of the writer (run again on every reconnect): durability per StoreOptions::sync, and how
// long a write waits for the database-wide write lock before it fails with kBusy.
std::string writerSetup(const StoreOptions& o) {
  const char* sync = o.sync == StoreOptions::Sync::kFull     ? "on"
                     : o.sync == StoreOptions::Sync::kNormal ? "local"
                                                             : "off";
  return std::string("SET synchronous_commit = ") + sync +
         "; SET lock_timeout = " + std::to_string(std::max(1, o.busy_timeout_ms));
}

class PgMapStore final : public MapStore {
 public:
  explicit PgMapStore(const StoreOptions& options) : core_(options) {
    openSchema(core_.writer, core_.url);
    journal::load(core_);
    follower_ = std::make_unique<Follower>(core_, kFollowPollMs);
  }
  ~PgMapStore() override { follower_.reset(); }  // before core_

  // ---- Catalogue
  MapInfo createMap(const std::string& name, int dim) override;
  std::vector<MapInfo> listMaps() const override {
    std::shared_lock lock(core_.state_mutex);
    return core_.catalogue.infos();
  }
  std::optional<MapInfo> findMap(const std::string& name) const override {
    std::shared_lock lock(core_.state_mutex);
    return core_.catalogue.info(name);
  }
  std::vector<RobotInfo> listRobots(const std::string& map) const override;
  std::vector<SessionInfo> listSessions(const std::string& map, const std::string& robot) const override;
  std::optional<FingerprintSettings> mapSettings(const std::string& map) const override {
    return settings::read(core_, map);
  }
  std::vector<std::string> recordSettings(const std::string& map) override {
    return settings::recordMissing(core_, map);
  }

  // ---- Scans
  std::int64_t addScan(const NewScan& scan) override { return scans::add(core_, scan); }
  std::optional<ScanInfo> scanInfo(std::int64_t id) const override { return scans::info(core_, id); }
  std::shared_ptr<const Fingerprint> fingerprint(std::int64_t id) const override {
    return scans::fingerprint(core_, id);
  }
  std::shared_ptr<const ViewContext> viewContext(std::int64_t id, const ViewSearchConfig& config) const override {
    return core_.cache.views.get(id, config, [&] { return fingerprint(id); });
  }
  std::optional<LabelledScan> rawScan(std::int64_t id) const override { return scans::raw(core_, id); }
  std::optional<std::int64_t> findScan(const std::string& map, const std::string& robot, const std::string& session,
                                       std::int64_t seq) const override {
    return scans::find(core_, map, robot, session, seq);
  }
  std::optional<std::int64_t> previousScan(const std::string& map, const std::string& robot, const std::string& session,
                                           std::int64_t seq) const override {
    return scans::find(core_, map, robot, session, seq, scans::SeqMatch::kLatestBefore);
  }
  std::int64_t deleteSession(const std::string& map, const std::string& robot, const std::string& session) override {
    return scans::deleteSession(core_, map, robot, session);
  }
  std::int64_t deleteRobot(const std::string& map, const std::string& robot) override {
    return scans::deleteRobot(core_, map, robot);
  }
  std::int64_t deleteMap(const std::string& map) override { return scans::deleteMap(core_, map); }

  // ---- Descriptor indexes (rebuilt from the database on open: no snapshots)
  std::vector<SearchHit> search(const SearchRequest& request) const override {
    std::shared_lock lock(core_.state_mutex);
    return map_index::searchMap(core_.catalogue.map(request.map), request);
  }
  void snapshot() override {}

  // ---- Administration
  void backup(const std::string& dest) const override { admin::backup(core_, dest); }
  std::string integrityCheck() const override { return admin::integrityCheck(core_); }
  Stats stats(const std::string& map) const override { return admin::stats(core_, map); }

  // ---- Pose graph
  std::int64_t addLoop(const std::string& map, const LoopRecord& loop) override {
    return graph::addLoop(core_, map, loop);
  }
  std::vector<LoopRecord> loops(const std::string& map, std::int64_t after_id, std::int64_t limit) const override {
    return graph::loops(core_, map, after_id, limit);
  }
  std::vector<GraphNodeRecord> graphNodes(const std::string& map, std::int64_t after_scan) const override {
    return graph::nodes(core_, map, after_scan);
  }
  std::int64_t saveOptimised(const std::string& map, std::int64_t map_id, const std::vector<OptimisedPose>& poses,
                             const std::vector<SessionFrame>& frames, std::int64_t through_loop) override {
    return graph::saveOptimised(core_, map, map_id, poses, frames, through_loop);
  }
  std::vector<OptimisedPose> optimisedPoses(const std::string& map, const std::string& robot,
                                            const std::string& session, std::int64_t after_scan,
                                            std::int64_t limit) const override {
    return graph::optimisedPoses(core_, map, robot, session, after_scan, limit);
  }
  std::vector<SessionFrame> sessionFrames(const std::string& map) const override {
    return graph::sessionFrames(core_, map);
  }
  std::int64_t graphVersion(const std::string& map) const override {
    return graph::mapValue(core_, map, "SELECT graph_version FROM maps WHERE id = $1");
  }
  std::int64_t optimisedThroughLoop(const std::string& map) const override {
    return graph::mapValue(core_, map, "SELECT graph_loop FROM maps WHERE id = $1");
  }

  // ---- Replicas
  // ---- Places (lifelong maps)
  void setPlaces(const std::string& map, const std::vector<PlaceRecord>& records) override {
    places::set(core_, map, records);
  }
  std::vector<PlaceRecord> places(const std::string& map) const override { return places::all(core_, map); }
  std::optional<PlaceRecord> placeOf(std::int64_t scan_id) const override { return places::of(core_, scan_id); }
  std::int64_t placeVersions(const std::string& map, std::int64_t place_id) const override {
    return places::versions(core_, map, place_id);
  }
  Retired retireScans(const std::string& map, const std::vector<std::int64_t>& scans,
                      const std::vector<LoopRecord>& new_loops) override {
    return places::retire(core_, map, scans, new_loops);
  }

  bool shared() const override { return true; }
  GraphClaim claimGraph(std::int64_t map_id) override { return owner_.claim(map_id); }

 private:
  Core core_;
  GraphOwner owner_{core_.options.path, core_.options.stall_timeout_ms};
  std::unique_ptr<Follower> follower_;
};

MapInfo PgMapStore::createMap(const std::string& name, int dim) {
  validate::newMap(name, dim);
  WriteTx tx(core_);  // caught up: a map another replica created is in the catalogue
  {
    std::shared_lock lock(core_.state_mutex);
    if (const auto* m = core_.catalogue.find(name)) {
      if (m->dim != dim)
        throw StorageError(Code::kAlreadyExists,
                           "map '" + name + "' exists with descriptor dimension " + std::to_string(m->dim));
      return m->info();
    }
  }
  // bigserial never hands out an id twice: a map deleted and created again under its name is a new map.
  MapState state;
  state.id = tx.conn()
                 .query("INSERT INTO maps(name, descriptor_dim, created_at) VALUES($1, $2, $3) RETURNING id",
                        {name, dim, nowSeconds()})
                 .i64(0, 0);
  settings::write(tx.conn(), state.id, core_.options.settings);
  state.name = name;
  state.dim = dim;
  state.index = std::make_unique<DescriptorIndex>(dim, core_.options.index);
  const auto entry = tx.journal(Change::kMapCreated, state.id, state.id);
  MapInfo info;
  tx.commit(entry, [&] { info = core_.catalogue.add(std::move(state)).info(); });
  return info;
}

std::vector<RobotInfo> PgMapStore::listRobots(const std::string& map) const {
  const auto map_id = core_.mapId(map);
  auto db = core_.readers.acquire();
  const auto r = db->query(
      "SELECT r.name, (SELECT count(*) FROM scans s WHERE s.robot_id = r.id),"
      " (SELECT count(*) FROM sessions x WHERE x.robot_id = r.id) FROM robots r WHERE r.map_id = $1"
      " ORDER BY r.name COLLATE \"C\"",  // bytewise, as SQLite orders
      {map_id});
  std::vector<RobotInfo> out;
  for (int i = 0; i < r.rows(); ++i) out.push_back({r.text(i, 0), r.i64(i, 1), r.i64(i, 2)});
  return out;
}

std::vector<SessionInfo> PgMapStore::listSessions(const std::string& map, const std::string& robot) const {
  std::int64_t map_id;
  {
    std::shared_lock lock(core_.state_mutex);
    const MapState& m = core_.catalogue.map(map);
    if (!robot.empty()) m.requireRobot(robot);
    map_id = m.id;
  }
  auto db = core_.readers.acquire();
  const auto r = db->query(
      "SELECT r.name, x.name, count(s.id), coalesce(min(s.seq), 0), coalesce(max(s.seq), 0)"
      " FROM sessions x JOIN robots r ON r.id = x.robot_id LEFT JOIN scans s ON s.session_id = x.id"
      " WHERE r.map_id = $1 AND ($2 = '' OR r.name = $2) GROUP BY x.id, r.name, x.name"
      " ORDER BY r.name COLLATE \"C\", x.name COLLATE \"C\"",
      {map_id, robot});
  std::vector<SessionInfo> out;
  for (int i = 0; i < r.rows(); ++i) out.push_back({r.text(i, 0), r.text(i, 1), r.i64(i, 2), r.i64(i, 3), r.i64(i, 4)});
  return out;
}

}  // namespace

Core::Core(const StoreOptions& o)
    : options(o),
      url(redacted(o.path)),
      writer(o.path, writerSetup(o)),
      readers(o.path),
      cache(static_cast<std::size_t>(std::max(0.0, o.cache_mb) * 1024 * 1024)) {}

std::unique_ptr<MapStore> open(const StoreOptions& options) { return std::make_unique<PgMapStore>(options); }

}  // namespace sglc::storage::pg
