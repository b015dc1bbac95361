#include "sglc/storage/map_store.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <random>
#include <shared_mutex>

#include "descriptor_index.hpp"
#include "fair_shared_mutex.hpp"
#include "fingerprint_cache.hpp"
#include "process_lock.hpp"
#include "sglc/names.hpp"
#include "sqlite.hpp"

namespace sglc::storage {
namespace {

namespace fs = std::filesystem;
using Code = StorageError::Code;

constexpr std::int32_t kApplicationId = 0x53474C43;  // "SGLC": marks our SQLite files

double nowSeconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// Forward migrations: kMigrations[v] upgrades a file from user_version v to v + 1.
const std::vector<const char*> kMigrations = {
    // 0 -> 1: the initial schema.
    R"sql(
    CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
    CREATE TABLE maps(
      id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, descriptor_dim INTEGER NOT NULL,
      created_at REAL NOT NULL, generation INTEGER NOT NULL DEFAULT 0);
    CREATE TABLE robots(
      id INTEGER PRIMARY KEY, map_id INTEGER NOT NULL REFERENCES maps(id), name TEXT NOT NULL,
      UNIQUE(map_id, name));
    CREATE TABLE sessions(
      id INTEGER PRIMARY KEY, robot_id INTEGER NOT NULL REFERENCES robots(id), name TEXT NOT NULL,
      created_at REAL NOT NULL, UNIQUE(robot_id, name));
    CREATE TABLE scans(
      id INTEGER PRIMARY KEY AUTOINCREMENT, map_id INTEGER NOT NULL REFERENCES maps(id),
      robot_id INTEGER NOT NULL REFERENCES robots(id), session_id INTEGER NOT NULL REFERENCES sessions(id),
      seq INTEGER NOT NULL, stamp REAL, pose BLOB, descriptor BLOB NOT NULL,
      fingerprint_bytes INTEGER NOT NULL, has_raw INTEGER NOT NULL, created_at REAL NOT NULL,
      UNIQUE(session_id, seq));
    CREATE INDEX scans_by_map ON scans(map_id, id);
    -- Large payloads apart, so that rebuilding the index reads only the small rows above.
    CREATE TABLE scan_blobs(
      scan_id INTEGER PRIMARY KEY REFERENCES scans(id), fingerprint BLOB NOT NULL, raw BLOB);
    )sql",
    // 1 -> 2: the pose graph (verified loops, optimised poses, session frames).
    R"sql(
    CREATE TABLE loops(
      id INTEGER PRIMARY KEY AUTOINCREMENT, map_id INTEGER NOT NULL REFERENCES maps(id),
      query_scan INTEGER NOT NULL REFERENCES scans(id), candidate_scan INTEGER NOT NULL REFERENCES scans(id),
      t BLOB NOT NULL, score REAL NOT NULL, inliers INTEGER NOT NULL, fitness REAL NOT NULL, rmse REAL NOT NULL,
      created_at REAL NOT NULL, UNIQUE(query_scan, candidate_scan));
    CREATE INDEX loops_by_map ON loops(map_id, id);
    CREATE INDEX loops_by_candidate ON loops(candidate_scan);
    CREATE TABLE optimised_poses(scan_id INTEGER PRIMARY KEY REFERENCES scans(id), pose BLOB NOT NULL);
    CREATE TABLE session_frames(
      session_id INTEGER PRIMARY KEY REFERENCES sessions(id), t BLOB NOT NULL, connected INTEGER NOT NULL);
    ALTER TABLE maps ADD COLUMN graph_version INTEGER NOT NULL DEFAULT 0;
    )sql",
    // 2 -> 3: the information matrix of each loop's pose (36 doubles; NULL for loops recorded before).
    R"sql(
    ALTER TABLE loops ADD COLUMN information BLOB;
    )sql",
    // 3 -> 4: the last loop the stored optimised poses account for (0: unknown, all loops are new).
    R"sql(
    ALTER TABLE maps ADD COLUMN graph_loop INTEGER NOT NULL DEFAULT 0;
    )sql",
};

// The first `rows` rows of M, row-major, as native doubles.
template <typename M>
std::vector<std::uint8_t> rowsBlob(const M& m, int rows) {
  std::vector<std::uint8_t> out(static_cast<std::size_t>(rows * m.cols()) * sizeof(double));
  for (int k = 0; k < rows * m.cols(); ++k) {
    const double v = m(k / m.cols(), k % m.cols());
    std::memcpy(&out[static_cast<std::size_t>(k) * sizeof(double)], &v, sizeof(double));
  }
  return out;
}

std::vector<std::uint8_t> informationBlob(const Mat6d& I) { return rowsBlob(I, 6); }
std::vector<std::uint8_t> poseBlob(const Mat4d& T) { return rowsBlob(T, 3); }  // the last row is implied

// The inverse of rowsBlob: fills the first `rows` rows of `m` (the rest keep their values); false when the
// blob has the wrong size.
template <typename M>
bool fromRowsBlob(std::span<const std::uint8_t> blob, int rows, M& m) {
  if (blob.size() != static_cast<std::size_t>(rows * m.cols()) * sizeof(double)) return false;
  for (int k = 0; k < rows * m.cols(); ++k) {
    double v;
    std::memcpy(&v, &blob[static_cast<std::size_t>(k) * sizeof(double)], sizeof(double));
    m(k / m.cols(), k % m.cols()) = v;
  }
  return true;
}

std::optional<Mat4d> poseFrom(std::span<const std::uint8_t> blob) {
  Mat4d T = Mat4d::Identity();
  return fromRowsBlob(blob, 3, T) ? std::optional<Mat4d>(T) : std::nullopt;
}

std::vector<std::uint8_t> rawBlob(const LabelledScan& scan) {
  std::vector<std::uint8_t> out(scan.points.size() * 16);
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    std::memcpy(&out[i * 16], scan.points[i].data(), 12);
    std::memcpy(&out[i * 16 + 12], &scan.labels[i], 4);
  }
  return out;
}

void checkName(const std::string& what, const std::string& name) {
  if (const auto error = nameError(name)) throw StorageError(Code::kInvalidArgument, what + " name " + *error);
}

struct MapState {
  std::int64_t id = 0;
  std::string name;
  int dim = 0;
  std::int64_t generation = 0;
  std::map<std::string, std::int64_t> robots;                             // name -> id
  std::map<std::pair<std::int64_t, std::string>, std::int64_t> sessions;  // (robot id, name) -> id
  std::unique_ptr<DescriptorIndex> index;
};

class SqliteMapStore final : public MapStore {
 public:
  explicit SqliteMapStore(const StoreOptions& options)
      : options_(options), cache_(static_cast<std::size_t>(std::max(0.0, options.cache_mb) * 1024 * 1024)) {
    openDatabase();
    loadCatalogue();
  }

  ~SqliteMapStore() override {
    try {
      if (options_.snapshot_index) snapshot();
    } catch (const std::exception&) {
      // A missing snapshot only costs a rebuild on the next open.
    }
  }

  MapInfo createMap(const std::string& name, int dim) override {
    checkName("map", name);
    if (dim <= 0 || dim > 65536) throw StorageError(Code::kInvalidArgument, "descriptor dimension must be 1..65536");
    std::lock_guard write(write_mutex_);
    {
      std::shared_lock lock(state_mutex_);
      if (auto it = maps_.find(name); it != maps_.end()) {
        if (it->second.dim != dim)
          throw StorageError(Code::kAlreadyExists,
                             "map '" + name + "' exists with descriptor dimension " + std::to_string(it->second.dim));
        return infoLocked(it->second);
      }
    }
    sql::Transaction tx(writer_);
    sql::Stmt(writer_, "INSERT INTO maps(name, descriptor_dim, created_at) VALUES(?, ?, ?)")
        .bind(1, name)
        .bind(2, static_cast<std::int64_t>(dim))
        .bind(3, nowSeconds())
        .run();
    MapState state;
    state.id = sqlite3_last_insert_rowid(writer_.get());
    state.name = name;
    state.dim = dim;
    state.index = std::make_unique<DescriptorIndex>(dim, options_.index);
    std::unique_lock lock(state_mutex_);
    tx.commit();
    auto& inserted = maps_[name] = std::move(state);
    map_names_[inserted.id] = name;
    return infoLocked(inserted);
  }

  std::vector<MapInfo> listMaps() const override {
    std::shared_lock lock(state_mutex_);
    std::vector<MapInfo> out;
    for (const auto& [name, m] : maps_) out.push_back(infoLocked(m));
    return out;
  }

  std::optional<MapInfo> findMap(const std::string& name) const override {
    std::shared_lock lock(state_mutex_);
    auto it = maps_.find(name);
    if (it == maps_.end()) return std::nullopt;
    return infoLocked(it->second);
  }

  std::vector<RobotInfo> listRobots(const std::string& map) const override {
    std::shared_lock lock(state_mutex_);
    const MapState& m = mapLocked(map);
    auto reader = acquireReader();
    sql::Stmt st(*reader,
                 "SELECT r.name, (SELECT count(*) FROM scans s WHERE s.robot_id = r.id),"
                 " (SELECT count(*) FROM sessions x WHERE x.robot_id = r.id)"
                 " FROM robots r WHERE r.map_id = ? ORDER BY r.name");
    st.bind(1, m.id);
    std::vector<RobotInfo> out;
    while (st.step()) out.push_back({st.text(0), st.i64(1), st.i64(2)});
    return out;
  }

  std::vector<SessionInfo> listSessions(const std::string& map, const std::string& robot) const override {
    std::shared_lock lock(state_mutex_);
    const MapState& m = mapLocked(map);
    if (!robot.empty() && !m.robots.count(robot))
      throw StorageError(Code::kNotFound, "map '" + map + "' has no robot '" + robot + "'");
    auto reader = acquireReader();
    sql::Stmt st(*reader,
                 "SELECT r.name, x.name, count(s.id), coalesce(min(s.seq), 0), coalesce(max(s.seq), 0)"
                 " FROM sessions x JOIN robots r ON r.id = x.robot_id LEFT JOIN scans s ON s.session_id = x.id"
                 " WHERE r.map_id = ? AND (? = '' OR r.name = ?) GROUP BY x.id ORDER BY r.name, x.name");
    st.bind(1, m.id).bind(2, robot).bind(3, robot);
    std::vector<SessionInfo> out;
    while (st.step()) out.push_back({st.text(0), st.text(1), st.i64(2), st.i64(3), st.i64(4)});
    return out;
  }

  std::int64_t addScan(const NewScan& scan) override {
    if (!scan.fingerprint) throw StorageError(Code::kInvalidArgument, "scan has no fingerprint");
    checkName("robot", scan.robot);
    checkName("session", scan.session);
    if (scan.stamp && !std::isfinite(*scan.stamp)) throw StorageError(Code::kInvalidArgument, "stamp is not finite");
    if (scan.odometry_pose && !scan.odometry_pose->allFinite())
      throw StorageError(Code::kInvalidArgument, "odometry pose is not finite");
    const auto& descriptor = scan.fingerprint->descriptor;
    for (float v : descriptor)
      if (!std::isfinite(v)) throw StorageError(Code::kInvalidArgument, "descriptor is not finite");
    const auto blob = serialize(*scan.fingerprint);
    const auto raw = scan.raw ? rawBlob(*scan.raw) : std::vector<std::uint8_t>();

    std::lock_guard write(write_mutex_);  // one writer at a time; readers continue until the commit
    MapState* m;
    {
      std::shared_lock lock(state_mutex_);
      m = &mutableMapLocked(scan.map);
    }
    if (static_cast<int>(descriptor.size()) != m->dim)
      throw StorageError(Code::kInvalidArgument, "descriptor has " + std::to_string(descriptor.size()) +
                                                     " values, map '" + scan.map + "' needs " + std::to_string(m->dim));
    sql::Transaction tx(writer_);
    bool new_robot = false, new_session = false;
    std::int64_t robot_id, session_id;
    if (auto it = m->robots.find(scan.robot); it != m->robots.end()) {
      robot_id = it->second;
    } else {
      sql::Stmt(writer_, "INSERT INTO robots(map_id, name) VALUES(?, ?)").bind(1, m->id).bind(2, scan.robot).run();
      robot_id = sqlite3_last_insert_rowid(writer_.get());
      new_robot = true;
    }
    if (auto it = m->sessions.find({robot_id, scan.session}); it != m->sessions.end()) {
      session_id = it->second;
    } else {
      sql::Stmt(writer_, "INSERT INTO sessions(robot_id, name, created_at) VALUES(?, ?, ?)")
          .bind(1, robot_id)
          .bind(2, scan.session)
          .bind(3, nowSeconds())
          .run();
      session_id = sqlite3_last_insert_rowid(writer_.get());
      new_session = true;
    }
    std::int64_t scan_id;
    {
      sql::Stmt st(writer_,
                   "INSERT INTO scans(map_id, robot_id, session_id, seq, stamp, pose, descriptor, fingerprint_bytes,"
                   " has_raw, created_at) VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?)");
      st.bind(1, m->id).bind(2, robot_id).bind(3, session_id).bind(4, scan.seq);
      if (scan.stamp)
        st.bind(5, *scan.stamp);
      else
        st.bindNull(5);
      std::vector<std::uint8_t> pose;
      if (scan.odometry_pose) {
        pose = poseBlob(*scan.odometry_pose);
        st.bindBlob(6, pose);
      } else {
        st.bindNull(6);
      }
      st.bindBlob(7, {reinterpret_cast<const std::uint8_t*>(descriptor.data()), descriptor.size() * sizeof(float)});
      st.bind(8, static_cast<std::int64_t>(blob.size()));
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
      scan_id = sqlite3_last_insert_rowid(writer_.get());
    }
    {
      sql::Stmt st(writer_, "INSERT INTO scan_blobs(scan_id, fingerprint, raw) VALUES(?, ?, ?)");
      st.bind(1, scan_id).bindBlob(2, blob);
      if (scan.raw)
        st.bindBlob(3, raw);
      else
        st.bindNull(3);
      st.run();
    }
    sql::Stmt(writer_, "UPDATE maps SET generation = generation + 1 WHERE id = ?").bind(1, m->id).run();

    IndexEntry entry{scan_id, robot_id, session_id, scan.seq, scan.stamp ? *scan.stamp : std::nan(""), false};
    // The commit and the index update happen under the exclusive lock: no reader sees one without the other.
    std::unique_lock lock(state_mutex_);
    tx.commit();
    m->generation += 1;
    if (new_robot) m->robots[scan.robot] = robot_id;
    if (new_session) m->sessions[{robot_id, scan.session}] = session_id;
    m->index->add(entry, descriptor.data());
    return scan_id;
  }

  std::vector<SearchHit> search(const SearchRequest& req) const override {
    std::shared_lock lock(state_mutex_);
    const MapState& m = mapLocked(req.map);
    if (static_cast<int>(req.descriptor.size()) != m.dim)
      throw StorageError(Code::kInvalidArgument, "query descriptor has " + std::to_string(req.descriptor.size()) +
                                                     " values, map '" + req.map + "' needs " + std::to_string(m.dim));
    for (float v : req.descriptor)
      if (!std::isfinite(v)) throw StorageError(Code::kInvalidArgument, "query descriptor is not finite");
    if (req.k <= 0 || req.k > 10000) throw StorageError(Code::kInvalidArgument, "k must be 1..10000");
    SearchFilter filter;
    filter.self_stamp = req.self_stamp ? *req.self_stamp : std::nan("");
    filter.exclude_seconds = req.exclude_seconds;
    filter.exclude_recent = req.exclude_recent;
    filter.self_seq = req.self_seq;
    auto robotId = [&](const std::string& name) -> std::int64_t {
      auto it = m.robots.find(name);
      return it == m.robots.end() ? -2 : it->second;  // -2 matches nothing
    };
    for (const auto& r : req.robots) filter.robots.insert(robotId(r));
    for (const auto& r : req.exclude_robots) filter.exclude_robots.insert(robotId(r));
    for (const auto& s : req.sessions) {
      const auto slash = s.find('/');
      if (slash == std::string::npos)
        throw StorageError(Code::kInvalidArgument, "session filter '" + s + "' must be 'robot/session'");
      auto it = m.sessions.find({robotId(s.substr(0, slash)), s.substr(slash + 1)});
      filter.sessions.insert(it == m.sessions.end() ? -2 : it->second);
    }
    for (const auto& [robot, session] : req.session_refs) {
      auto it = m.sessions.find({robotId(robot), session});
      filter.sessions.insert(it == m.sessions.end() ? -2 : it->second);
    }
    filter.exclude_scans.insert(req.exclude_scan_ids.begin(), req.exclude_scan_ids.end());
    if (!req.self_robot.empty()) {
      filter.self_robot = robotId(req.self_robot);
      auto it = m.sessions.find({filter.self_robot, req.self_session});
      filter.self_session = it == m.sessions.end() ? -2 : it->second;
    }
    return m.index->search(req.descriptor.data(), req.k, filter);
  }

  std::optional<ScanInfo> scanInfo(std::int64_t scan_id) const override {
    std::shared_lock lock(state_mutex_);
    auto reader = acquireReader();
    sql::Stmt st(*reader,
                 "SELECT s.map_id, r.name, x.name, s.seq, s.stamp, s.pose, s.fingerprint_bytes, s.has_raw"
                 " FROM scans s JOIN robots r ON r.id = s.robot_id JOIN sessions x ON x.id = s.session_id"
                 " WHERE s.id = ?");
    st.bind(1, scan_id);
    if (!st.step()) return std::nullopt;
    ScanInfo info;
    info.id = scan_id;
    auto name = map_names_.find(st.i64(0));
    info.map = name == map_names_.end() ? std::string() : name->second;
    info.robot = st.text(1);
    info.session = st.text(2);
    info.seq = st.i64(3);
    if (!st.isNull(4)) info.stamp = st.f64(4);
    if (!st.isNull(5)) info.odometry_pose = poseFrom(st.blob(5));
    info.fingerprint_bytes = st.i64(6);
    info.has_raw = st.i64(7) != 0;
    return info;
  }

  std::shared_ptr<const Fingerprint> fingerprint(std::int64_t scan_id) const override {
    if (auto hit = cache_.get(scan_id)) return hit;
    std::shared_ptr<const Fingerprint> fp;
    {
      std::shared_lock lock(state_mutex_);
      auto reader = acquireReader();
      sql::Stmt st(*reader, "SELECT fingerprint FROM scan_blobs WHERE scan_id = ?");
      st.bind(1, scan_id);
      if (!st.step()) return nullptr;
      try {
        fp = std::make_shared<const Fingerprint>(deserialize(st.blob(0)));
      } catch (const InputError& e) {
        throw StorageError(Code::kCorrupt, "scan " + std::to_string(scan_id) + ": " + e.what());
      }
    }
    cache_.put(scan_id, fp);
    return fp;
  }

  std::optional<LabelledScan> rawScan(std::int64_t scan_id) const override {
    std::shared_lock lock(state_mutex_);
    auto reader = acquireReader();
    sql::Stmt st(*reader, "SELECT raw FROM scan_blobs WHERE scan_id = ?");
    st.bind(1, scan_id);
    if (!st.step() || st.isNull(0)) return std::nullopt;
    const auto blob = st.blob(0);
    if (blob.size() % 16 != 0)
      throw StorageError(Code::kCorrupt, "scan " + std::to_string(scan_id) + ": raw cloud has a bad length");
    LabelledScan scan;
    scan.points.resize(blob.size() / 16);
    scan.labels.resize(blob.size() / 16);
    for (std::size_t i = 0; i < scan.points.size(); ++i) {
      std::memcpy(scan.points[i].data(), &blob[i * 16], 12);
      std::memcpy(&scan.labels[i], &blob[i * 16 + 12], 4);
    }
    return scan;
  }

  std::optional<std::int64_t> findScan(const std::string& map, const std::string& robot, const std::string& session,
                                       std::int64_t seq) const override {
    std::shared_lock lock(state_mutex_);
    const MapState& m = mapLocked(map);
    auto r = m.robots.find(robot);
    if (r == m.robots.end()) return std::nullopt;
    auto s = m.sessions.find({r->second, session});
    if (s == m.sessions.end()) return std::nullopt;
    auto reader = acquireReader();
    sql::Stmt st(*reader, "SELECT id FROM scans WHERE session_id = ? AND seq = ?");
    st.bind(1, s->second).bind(2, seq);
    if (!st.step()) return std::nullopt;
    return st.i64(0);
  }

  std::int64_t deleteSession(const std::string& map, const std::string& robot, const std::string& session) override {
    std::lock_guard write(write_mutex_);
    MapState* m;
    std::int64_t session_id;
    {
      std::shared_lock lock(state_mutex_);
      m = &mutableMapLocked(map);
      auto r = m->robots.find(robot);
      if (r == m->robots.end()) throw StorageError(Code::kNotFound, "map '" + map + "' has no robot '" + robot + "'");
      auto s = m->sessions.find({r->second, session});
      if (s == m->sessions.end())
        throw StorageError(Code::kNotFound, "robot '" + robot + "' has no session '" + session + "'");
      session_id = s->second;
    }
    return deleteWhere(
        *m, "session_id = ?", session_id,
        [&] {
          for (auto it = m->sessions.begin(); it != m->sessions.end();)
            it = it->second == session_id ? m->sessions.erase(it) : std::next(it);
        },
        "DELETE FROM sessions WHERE id = ?");
  }

  std::int64_t deleteRobot(const std::string& map, const std::string& robot) override {
    std::lock_guard write(write_mutex_);
    MapState* m;
    std::int64_t robot_id;
    {
      std::shared_lock lock(state_mutex_);
      m = &mutableMapLocked(map);
      auto r = m->robots.find(robot);
      if (r == m->robots.end()) throw StorageError(Code::kNotFound, "map '" + map + "' has no robot '" + robot + "'");
      robot_id = r->second;
    }
    return deleteWhere(
        *m, "robot_id = ?", robot_id,
        [&] {
          m->robots.erase(robot);
          for (auto it = m->sessions.begin(); it != m->sessions.end();)
            it = it->first.first == robot_id ? m->sessions.erase(it) : std::next(it);
        },
        "DELETE FROM sessions WHERE robot_id = ?; DELETE FROM robots WHERE id = ?");
  }

  void backup(const std::string& dest) const override {
    // Claim the name first (O_EXCL): of two backups to one name only one proceeds, and a failure removes only
    // the file this call created. VACUUM INTO accepts an existing empty file.
    const int fd = ::open(dest.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) {
      const int e = errno;
      if (e == EEXIST) throw StorageError(Code::kAlreadyExists, "the backup target already exists", dest);
      throw StorageError(e == EACCES || e == EROFS || e == EPERM ? Code::kReadOnly
                         : e == ENOSPC || e == EDQUOT            ? Code::kFull
                                                                 : Code::kIo,
                         "the backup file cannot be created", dest + ": " + std::strerror(e));
    }
    ::close(fd);
    auto reader = acquireReader();
    try {
      sql::Stmt st(*reader, "VACUUM INTO ?");
      st.bind(1, dest);
      st.run();
    } catch (const StorageError& e) {
      std::error_code ec;
      fs::remove(dest, ec);
      throw StorageError(e.code(), std::string("the backup could not be written: ") + e.what(),
                         e.detail().empty() ? std::string(e.what()) : e.detail());
    }
  }

  // ---- Pose graph
  std::int64_t addLoop(const std::string& map, const LoopRecord& loop) override {
    if (!loop.T.allFinite() || !std::isfinite(loop.score) || !std::isfinite(loop.fitness) ||
        !std::isfinite(loop.rmse) || (loop.information && !loop.information->allFinite()))
      throw StorageError(Code::kInvalidArgument, "loop has a non-finite value");
    if (loop.query_scan == loop.candidate_scan) throw StorageError(Code::kInvalidArgument, "a loop needs two scans");
    std::lock_guard write(write_mutex_);
    std::int64_t map_id;
    {
      std::shared_lock lock(state_mutex_);
      map_id = mapLocked(map).id;
    }
    sql::Transaction tx(writer_);
    for (const auto scan : {loop.query_scan, loop.candidate_scan}) {
      sql::Stmt st(writer_, "SELECT 1 FROM scans WHERE id = ? AND map_id = ?");
      st.bind(1, scan).bind(2, map_id);
      if (!st.step()) throw StorageError(Code::kNotFound, "map '" + map + "' has no scan " + std::to_string(scan));
    }
    const auto t = poseBlob(loop.T);
    sql::Stmt(writer_, "DELETE FROM loops WHERE query_scan = ? AND candidate_scan = ?")
        .bind(1, loop.query_scan)
        .bind(2, loop.candidate_scan)
        .run();
    sql::Stmt st(writer_,
                 "INSERT INTO loops(map_id, query_scan, candidate_scan, t, score, inliers, fitness, rmse, created_at,"
                 " information) VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?)");
    st.bind(1, map_id).bind(2, loop.query_scan).bind(3, loop.candidate_scan).bindBlob(4, t).bind(5, loop.score);
    st.bind(6, static_cast<std::int64_t>(loop.inliers)).bind(7, loop.fitness).bind(8, loop.rmse).bind(9, nowSeconds());
    const auto info = loop.information ? informationBlob(*loop.information) : std::vector<std::uint8_t>{};
    if (loop.information)
      st.bindBlob(10, info);
    else
      st.bindNull(10);
    st.run();
    const auto id = sqlite3_last_insert_rowid(writer_.get());
    tx.commit();
    return id;
  }

  std::vector<LoopRecord> loops(const std::string& map, std::int64_t after_id) const override {
    const auto map_id = mapId(map);
    auto reader = acquireReader();
    sql::Stmt st(*reader,
                 "SELECT id, query_scan, candidate_scan, t, score, inliers, fitness, rmse, information FROM loops"
                 " WHERE map_id = ? AND id > ? ORDER BY id");
    st.bind(1, map_id).bind(2, after_id);
    std::vector<LoopRecord> out;
    while (st.step()) {
      LoopRecord r;
      r.id = st.i64(0);
      r.query_scan = st.i64(1);
      r.candidate_scan = st.i64(2);
      const auto T = poseFrom(st.blob(3));
      if (!T) throw StorageError(Code::kCorrupt, "loop " + std::to_string(r.id) + " has a damaged transform");
      r.T = *T;
      r.score = st.f64(4);
      r.inliers = static_cast<int>(st.i64(5));
      r.fitness = st.f64(6);
      r.rmse = st.f64(7);
      if (!st.isNull(8)) {
        Mat6d I;
        if (!fromRowsBlob(st.blob(8), 6, I))
          throw StorageError(Code::kCorrupt, "loop " + std::to_string(r.id) + " has a damaged information matrix");
        r.information = I;
      }
      out.push_back(r);
    }
    return out;
  }

  std::vector<GraphNodeRecord> graphNodes(const std::string& map, std::int64_t after_scan) const override {
    const auto map_id = mapId(map);
    auto reader = acquireReader();
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
      if (!st.isNull(6)) n.odometry_pose = poseFrom(st.blob(6));
      out.push_back(std::move(n));
    }
    return out;
  }

  std::int64_t saveOptimised(const std::string& map, const std::vector<OptimisedPose>& poses,
                             const std::vector<SessionFrame>& frames, std::int64_t through_loop) override {
    for (const auto& p : poses)
      if (!p.pose.allFinite()) throw StorageError(Code::kInvalidArgument, "optimised pose is not finite");
    for (const auto& f : frames)
      if (!f.T_map_session.allFinite()) throw StorageError(Code::kInvalidArgument, "session frame is not finite");
    std::lock_guard write(write_mutex_);
    std::int64_t map_id;
    {
      std::shared_lock lock(state_mutex_);
      map_id = mapLocked(map).id;
    }
    sql::Transaction tx(writer_);
    {
      sql::Stmt st(writer_,
                   "INSERT OR REPLACE INTO optimised_poses(scan_id, pose)"
                   " SELECT ?1, ?2 WHERE EXISTS(SELECT 1 FROM scans WHERE id = ?1 AND map_id = ?3)");
      for (const auto& p : poses) {
        const auto blob = poseBlob(p.pose);
        st.bind(1, p.scan_id).bindBlob(2, blob).bind(3, map_id);
        st.run();
        st.reset();
      }
    }
    {
      sql::Stmt st(writer_,
                   "INSERT OR REPLACE INTO session_frames(session_id, t, connected)"
                   " SELECT ?1, ?2, ?3 WHERE EXISTS(SELECT 1 FROM sessions e JOIN robots r ON r.id = e.robot_id"
                   " WHERE e.id = ?1 AND r.map_id = ?4)");
      for (const auto& f : frames) {
        const auto blob = poseBlob(f.T_map_session);
        st.bind(1, f.session_id).bindBlob(2, blob).bind(3, static_cast<std::int64_t>(f.connected)).bind(4, map_id);
        st.run();
        st.reset();
      }
    }
    sql::Stmt(writer_, "UPDATE maps SET graph_version = graph_version + 1, graph_loop = ?2 WHERE id = ?1")
        .bind(1, map_id)
        .bind(2, through_loop)
        .run();
    sql::Stmt v(writer_, "SELECT graph_version FROM maps WHERE id = ?");
    v.bind(1, map_id);
    const std::int64_t version = v.step() ? v.i64(0) : 0;
    v.reset();
    tx.commit();
    return version;
  }

  std::vector<OptimisedPose> optimisedPoses(const std::string& map, const std::string& robot,
                                            const std::string& session, std::int64_t after_scan,
                                            std::int64_t limit) const override {
    const auto map_id = mapId(map);
    auto reader = acquireReader();
    sql::Stmt st(*reader,
                 "SELECT o.scan_id, o.pose FROM optimised_poses o JOIN scans s ON s.id = o.scan_id"
                 " JOIN sessions e ON e.id = s.session_id JOIN robots r ON r.id = s.robot_id"
                 " WHERE s.map_id = ?1 AND o.scan_id > ?2 AND (?3 = '' OR r.name = ?3) AND (?4 = '' OR e.name = ?4)"
                 " ORDER BY o.scan_id LIMIT ?5");
    st.bind(1, map_id).bind(2, after_scan).bind(3, robot).bind(4, session).bind(5, limit);
    std::vector<OptimisedPose> out;
    while (st.step()) {
      const auto T = poseFrom(st.blob(1));
      if (!T) throw StorageError(Code::kCorrupt, "scan " + std::to_string(st.i64(0)) + " has a damaged optimised pose");
      out.push_back({st.i64(0), *T});
    }
    return out;
  }

  std::vector<SessionFrame> sessionFrames(const std::string& map) const override {
    const auto map_id = mapId(map);
    auto reader = acquireReader();
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
      const auto T = poseFrom(st.blob(3));
      if (!T) throw StorageError(Code::kCorrupt, "session " + std::to_string(f.session_id) + " has a damaged frame");
      f.T_map_session = *T;
      f.connected = st.i64(4) != 0;
      out.push_back(std::move(f));
    }
    return out;
  }

  std::int64_t graphVersion(const std::string& map) const override { return mapRowValue(map, "graph_version"); }
  std::int64_t optimisedThroughLoop(const std::string& map) const override { return mapRowValue(map, "graph_loop"); }

  std::string integrityCheck() const override {
    auto reader = acquireReader();
    sql::Stmt st(*reader, "PRAGMA integrity_check");
    std::string out;
    while (st.step()) out += (out.empty() ? "" : "\n") + st.text(0);
    return out;
  }

  Stats stats(const std::string& map) const override {
    std::shared_lock lock(state_mutex_);
    Stats s;
    auto reader = acquireReader();
    std::int64_t map_id = -1;
    if (!map.empty()) map_id = mapLocked(map).id;
    s.maps = map.empty() ? static_cast<std::int64_t>(maps_.size()) : 1;
    for (const auto& [name, m] : maps_) {
      if (map_id >= 0 && m.id != map_id) continue;
      s.robots += static_cast<std::int64_t>(m.robots.size());
      s.sessions += static_cast<std::int64_t>(m.sessions.size());
      s.index_entries += m.index->live();
    }
    sql::Stmt st(*reader, "SELECT count(*), coalesce(sum(fingerprint_bytes), 0) FROM scans WHERE ? < 0 OR map_id = ?");
    st.bind(1, map_id).bind(2, map_id);
    if (st.step()) {
      s.scans = st.i64(0);
      s.fingerprint_bytes = st.i64(1);
    }
    std::error_code ec;
    for (const char* suffix : {"", "-wal"}) {
      const auto size = fs::file_size(options_.path + suffix, ec);
      if (!ec) s.db_bytes += static_cast<std::int64_t>(size);
    }
    s.cache_mb = static_cast<double>(cache_.usedBytes()) / (1024.0 * 1024.0);
    s.cache_hits = cache_.hits();
    s.cache_misses = cache_.misses();
    return s;
  }

  void snapshot() override {
    std::lock_guard write(write_mutex_);
    std::shared_lock lock(state_mutex_);
    std::error_code ec;
    fs::create_directories(snapshotDir(), ec);
    if (ec) throw StorageError(Code::kIo, snapshotDir() + ": " + ec.message());
    for (const auto& [name, m] : maps_) {
      const auto path = snapshotPath(m.id);
      if (m.index->hasTombstones()) {
        fs::remove(path, ec);  // the next open rebuilds without the deleted scans
        continue;
      }
      m.index->save(path, m.generation);
    }
  }

 private:
  // A pooled read-only connection.
  class ReaderLease {
   public:
    ReaderLease(const SqliteMapStore& store, sql::Db db) : store_(store), db_(std::move(db)) {}
    ReaderLease(ReaderLease&&) = default;
    ~ReaderLease() {
      if (db_) store_.releaseReader(std::move(db_));
    }
    const sql::Db& operator*() const { return db_; }

   private:
    const SqliteMapStore& store_;
    sql::Db db_;
  };

  ReaderLease acquireReader() const {
    {
      std::lock_guard lock(pool_mutex_);
      if (!pool_.empty()) {
        sql::Db db = std::move(pool_.back());
        pool_.pop_back();
        return ReaderLease(*this, std::move(db));
      }
    }
    return ReaderLease(*this, sql::Db(options_.path, SQLITE_OPEN_READONLY, options_.busy_timeout_ms));
  }

  void releaseReader(sql::Db db) const {
    std::lock_guard lock(pool_mutex_);
    if (pool_.size() < 16) pool_.push_back(std::move(db));
  }

  std::string snapshotDir() const { return options_.path + ".index"; }
  std::string snapshotPath(std::int64_t map_id) const {
    return snapshotDir() + "/map-" + std::to_string(map_id) + "-" + token_ + ".sgix";
  }

  void openDatabase() {
    if (options_.path.empty()) throw StorageError(Code::kInvalidArgument, "database path is empty");
    const fs::path path(options_.path);
    std::error_code ec;
    const bool existed = fs::exists(path, ec);
    if (existed && fs::is_directory(path, ec))
      throw StorageError(Code::kInvalidArgument, options_.path + ": is a directory, not a database file");
    if (!existed && path.has_parent_path()) {
      fs::create_directories(path.parent_path(), ec);
      if (ec)
        throw StorageError(
            ec == std::errc::permission_denied || ec == std::errc::read_only_file_system ? Code::kReadOnly : Code::kIo,
            path.parent_path().string() + ": cannot create directory: " + ec.message());
    }
    if (!existed) {
      const auto dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
      if (::access(dir.c_str(), W_OK) != 0)
        throw StorageError(Code::kReadOnly,
                           dir.string() + ": directory is not writable, cannot create " + options_.path);
    } else if (::access(options_.path.c_str(), W_OK) != 0) {
      throw StorageError(Code::kReadOnly, options_.path + ": database file is not writable");
    }
    lock_ = ProcessLock(options_.path);
    writer_ = sql::Db(options_.path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, options_.busy_timeout_ms);

    std::int64_t app_id = 0, version = 0, objects = 0;
    try {
      sql::Stmt a(writer_, "PRAGMA application_id");
      if (a.step()) app_id = a.i64(0);
      sql::Stmt v(writer_, "PRAGMA user_version");
      if (v.step()) version = v.i64(0);
      sql::Stmt o(writer_, "SELECT count(*) FROM sqlite_master");
      if (o.step()) objects = o.i64(0);
    } catch (const StorageError& e) {
      if (e.code() == Code::kCorrupt)
        throw StorageError(Code::kCorrupt, options_.path + ": not an SGLC map database (not SQLite, or damaged)");
      throw;
    }
    if (app_id != kApplicationId && !(app_id == 0 && objects == 0))
      throw StorageError(Code::kCorrupt, options_.path + ": a foreign SQLite database, not an SGLC map");
    if (version > kSchemaVersion)
      throw StorageError(Code::kNewerSchema, options_.path + ": schema version " + std::to_string(version) +
                                                 " is newer than this build supports (" +
                                                 std::to_string(kSchemaVersion) + "); upgrade the software");
    // WAL lets readers run during a write; it must be set outside a transaction.
    {
      sql::Stmt wal(writer_, "PRAGMA journal_mode=WAL");
      if (!wal.step() || wal.text(0) != "wal")
        throw StorageError(Code::kIo, options_.path + ": cannot switch to WAL journal mode");
    }
    const char* sync = options_.sync == StoreOptions::Sync::kFull     ? "FULL"
                       : options_.sync == StoreOptions::Sync::kNormal ? "NORMAL"
                                                                      : "OFF";
    writer_.exec(std::string("PRAGMA synchronous=") + sync);
    writer_.exec("PRAGMA foreign_keys=ON");
    if (options_.max_db_mb > 0) {
      const auto pages = static_cast<std::int64_t>(options_.max_db_mb * 1024 * 1024 / 4096);
      writer_.exec("PRAGMA max_page_count=" + std::to_string(std::max<std::int64_t>(pages, 16)));
    }
    // Forward migrations, each in its own transaction with the version bump.
    for (auto v = version; v < kSchemaVersion; ++v) {
      sql::Transaction tx(writer_);
      writer_.exec(kMigrations[static_cast<std::size_t>(v)]);
      if (v == 0) {
        std::random_device rd;
        const auto token = (static_cast<std::uint64_t>(rd()) << 32) ^ rd();
        sql::Stmt(writer_, "INSERT INTO meta(key, value) VALUES('token', ?)").bind(1, std::to_string(token)).run();
        writer_.exec("PRAGMA application_id=" + std::to_string(kApplicationId));
      }
      writer_.exec("PRAGMA user_version=" + std::to_string(v + 1));
      tx.commit();
    }
    sql::Stmt t(writer_, "SELECT value FROM meta WHERE key = 'token'");
    if (!t.step()) throw StorageError(Code::kCorrupt, options_.path + ": meta table has no token");
    token_ = t.text(0);
  }

  void loadCatalogue() {
    std::unique_lock lock(state_mutex_);
    {
      sql::Stmt st(writer_, "SELECT id, name, descriptor_dim, generation FROM maps ORDER BY id");
      while (st.step()) {
        MapState m;
        m.id = st.i64(0);
        m.name = st.text(1);
        m.dim = static_cast<int>(st.i64(2));
        m.generation = st.i64(3);
        m.index = std::make_unique<DescriptorIndex>(m.dim, options_.index);
        map_names_[m.id] = m.name;
        maps_[m.name] = std::move(m);
      }
    }
    for (auto& [name, m] : maps_) {
      sql::Stmt r(writer_, "SELECT id, name FROM robots WHERE map_id = ?");
      r.bind(1, m.id);
      while (r.step()) m.robots[r.text(1)] = r.i64(0);
      sql::Stmt s(writer_,
                  "SELECT x.id, x.robot_id, x.name FROM sessions x JOIN robots r ON r.id = x.robot_id"
                  " WHERE r.map_id = ?");
      s.bind(1, m.id);
      while (s.step()) m.sessions[{s.i64(1), s.text(2)}] = s.i64(0);
      if (options_.snapshot_index && m.index->load(snapshotPath(m.id), m.generation)) continue;
      rebuildIndex(m);
    }
  }

  void rebuildIndex(MapState& m) {
    std::vector<IndexEntry> entries;
    std::vector<float> vectors;
    sql::Stmt st(writer_,
                 "SELECT id, robot_id, session_id, seq, stamp, descriptor FROM scans WHERE map_id = ? ORDER BY id");
    st.bind(1, m.id);
    while (st.step()) {
      const auto blob = st.blob(5);
      if (blob.size() != static_cast<std::size_t>(m.dim) * sizeof(float))
        throw StorageError(Code::kCorrupt, options_.path + ": scan " + std::to_string(st.i64(0)) +
                                               " has a descriptor of the wrong length");
      entries.push_back({st.i64(0), st.i64(1), st.i64(2), st.i64(3), st.isNull(4) ? std::nan("") : st.f64(4), false});
      const auto* f = reinterpret_cast<const float*>(blob.data());
      vectors.insert(vectors.end(), f, f + m.dim);
    }
    m.index->build(std::move(entries), vectors);
  }

  template <typename UpdateCatalogue>
  std::int64_t deleteWhere(MapState& m, const char* where, std::int64_t id, UpdateCatalogue update,
                           const std::string& delete_parents) {
    sql::Transaction tx(writer_);
    std::unordered_set<std::int64_t> ids;
    {
      sql::Stmt st(writer_, (std::string("SELECT id FROM scans WHERE map_id = ? AND ") + where).c_str());
      st.bind(1, m.id).bind(2, id);
      while (st.step()) ids.insert(st.i64(0));
    }
    sql::Stmt(writer_,
              (std::string("DELETE FROM scan_blobs WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ? AND ") +
               where + ")")
                  .c_str())
        .bind(1, m.id)
        .bind(2, id)
        .run();
    // Pose-graph rows of the removed scans and sessions (?1 = map, ?2 = the id in `where`).
    std::string where2 = where;
    where2.replace(where2.find('?'), 1, "?2");
    for (const char* graph_rows :
         {"DELETE FROM loops WHERE query_scan IN (SELECT id FROM scans WHERE map_id = ?1 AND %) OR"
          " candidate_scan IN (SELECT id FROM scans WHERE map_id = ?1 AND %)",
          "DELETE FROM optimised_poses WHERE scan_id IN (SELECT id FROM scans WHERE map_id = ?1 AND %)",
          "DELETE FROM session_frames WHERE session_id IN (SELECT session_id FROM scans WHERE map_id = ?1 AND %)"}) {
      std::string text = graph_rows;
      for (auto at = text.find('%'); at != std::string::npos; at = text.find('%')) text.replace(at, 1, where2);
      sql::Stmt(writer_, text.c_str()).bind(1, m.id).bind(2, id).run();
    }
    sql::Stmt(writer_, (std::string("DELETE FROM scans WHERE map_id = ? AND ") + where).c_str())
        .bind(1, m.id)
        .bind(2, id)
        .run();
    // Parent rows (session, or sessions and robot): one statement each, all bound to the same id.
    std::size_t start = 0;
    while (start < delete_parents.size()) {
      auto end = delete_parents.find(';', start);
      if (end == std::string::npos) end = delete_parents.size();
      const auto stmt = delete_parents.substr(start, end - start);
      if (stmt.find_first_not_of(' ') != std::string::npos) sql::Stmt(writer_, stmt.c_str()).bind(1, id).run();
      start = end + 1;
    }
    sql::Stmt(writer_, "UPDATE maps SET generation = generation + 1 WHERE id = ?").bind(1, m.id).run();
    std::unique_lock lock(state_mutex_);
    tx.commit();
    m.generation += 1;
    const auto removed = m.index->remove(ids);
    update();
    for (auto sid : ids) cache_.erase(sid);
    return removed;
  }

  std::int64_t mapId(const std::string& map) const {
    std::shared_lock lock(state_mutex_);
    return mapLocked(map).id;
  }

  // An integer column of the map's row in `maps` (a fixed column name from this file, never user input).
  std::int64_t mapRowValue(const std::string& map, const char* column) const {
    const auto map_id = mapId(map);
    auto reader = acquireReader();
    const std::string query = std::string("SELECT ") + column + " FROM maps WHERE id = ?";
    sql::Stmt st(*reader, query.c_str());
    st.bind(1, map_id);
    return st.step() ? st.i64(0) : 0;
  }

  MapInfo infoLocked(const MapState& m) const {
    MapInfo info;
    info.id = m.id;
    info.name = m.name;
    info.descriptor_dim = m.dim;
    info.scans = m.index->live();
    info.robots = static_cast<std::int64_t>(m.robots.size());
    info.sessions = static_cast<std::int64_t>(m.sessions.size());
    return info;
  }

  const MapState& mapLocked(const std::string& name) const {
    auto it = maps_.find(name);
    if (it == maps_.end()) throw StorageError(Code::kNotFound, "no map named '" + name + "'");
    return it->second;
  }
  MapState& mutableMapLocked(const std::string& name) { return const_cast<MapState&>(mapLocked(name)); }

  StoreOptions options_;
  ProcessLock lock_;  // before writer_: released after the database is closed
  sql::Db writer_;
  std::string token_;
  mutable std::mutex write_mutex_;
  mutable FairSharedMutex state_mutex_;  // catalogue + indexes; exclusive only around commit + index update
  std::map<std::string, MapState> maps_;
  std::map<std::int64_t, std::string> map_names_;
  mutable std::mutex pool_mutex_;
  mutable std::vector<sql::Db> pool_;
  mutable FingerprintCache cache_;
};

}  // namespace

std::unique_ptr<MapStore> MapStore::open(const StoreOptions& options) {
  return std::make_unique<SqliteMapStore>(options);
}

}  // namespace sglc::storage
