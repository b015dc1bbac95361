// The persistent map database: SQLite is the source of truth (maps, robots, sessions, scans with their
// fingerprints), FAISS is the in-memory descriptor index, rebuilt from SQLite on open or loaded from a
// snapshot that matches it.
//
// Concurrency: any number of threads may call the const methods while one thread at a time writes (writers
// are serialised internally). A reader never sees a half-written scan, and the index and the database agree
// at every moment a reader can observe: a scan becomes visible to search() and to fetches in the same step.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "sglc/fingerprint.hpp"
#include "sglc/fingerprint_settings.hpp"
#include "sglc/types.hpp"
#include "sglc/view_context.hpp"

namespace sglc::storage {

// Every storage failure. `code` says what kind, so a service can map it to a status.
class StorageError : public std::runtime_error {
 public:
  enum class Code {
    kInvalidArgument,  // bad input (empty name, wrong descriptor length, ...)
    kNotFound,         // unknown map, robot, session or scan
    kAlreadyExists,    // duplicate (session, sequence number), map name taken
    kCorrupt,          // not a map database, or damaged
    kNewerSchema,      // written by a newer version of this software
    kReadOnly,         // the file or its directory cannot be written
    kFull,             // disk full
    kBusy,             // locked by another process for longer than the busy timeout
    kIo,               // any other I/O failure
    kUnavailable,      // the database server cannot be reached (PostgreSQL); worth a retry
  };
  StorageError(Code code, const std::string& message) : std::runtime_error(message), code_(code) {}
  // A failure of the database engine: `message` says what it means for the caller (no SQL, no paths), `detail`
  // what the engine said, for the operator's log.
  StorageError(Code code, const std::string& message, std::string detail)
      : std::runtime_error(message), code_(code), detail_(std::move(detail)) {}
  Code code() const { return code_; }
  const std::string& detail() const { return detail_; }

 private:
  Code code_;
  std::string detail_;
};

struct IndexOptions {
  enum class Type { kExact, kIvf };
  Type type = Type::kExact;   // exact (flat L2) or approximate (IVF-flat) search
  int ivf_nlist = 0;          // IVF cells; 0 = about sqrt(scans)
  int ivf_nprobe = 48;        // cells visited per search
  int ivf_min_scans = 20000;  // below this many scans an IVF map is searched exactly (training needs data)
};

struct StoreOptions {
  // A SQLite file, created (with its directory) if missing; or a PostgreSQL database as a libpq URL
  // (postgresql://user@host:port/dbname?sslmode=...), whose tables are created if missing. Several servers may
  // share one PostgreSQL database; a SQLite file is opened by one process at a time.
  std::string path;
  enum class Sync { kOff, kNormal, kFull };
  Sync sync = Sync::kFull;  // SQLite synchronous mode: kFull survives power loss, kNormal only process crashes
  int busy_timeout_ms = 5000;
  // PostgreSQL: a write transaction that sends nothing for this long (its process frozen: SIGSTOP, a paused
  // container, a VM stall) is ended by the server, which frees the write lock for the other replicas; the
  // frozen process finds its transaction gone when it resumes (kUnavailable) and reconnects. Its pose-graph
  // locks (claimGraph) go the same way after this long. 0: never.
  int stall_timeout_ms = 5000;
  // Fingerprints kept in memory (least recently used evicted); stored scans' view contexts get an eighth of it
  // more (at least 4 MB; none when 0).
  double cache_mb = 256;
  bool snapshot_index = true;  // save the FAISS indexes beside the database on close, load them on open
  double max_db_mb = 0;        // quota: writes beyond it fail with kFull (0: unlimited)
  IndexOptions index;
  // The settings this process makes fingerprints with (sglc::fingerprintSettings of its engine Config): recorded
  // with each map createMap creates, and by recordSettings with maps that have none. Empty: maps are created
  // without settings (tools and tests that make no fingerprints of their own).
  FingerprintSettings settings;
};

struct MapInfo {
  std::int64_t id = 0;
  std::string name;
  int descriptor_dim = 0;
  std::int64_t scans = 0;
  std::int64_t robots = 0;
  std::int64_t sessions = 0;
  // Deletions of sessions or robots the map has had since the store was opened (by any process, for a shared
  // store): a pose graph built before a change of it may hold deleted scans.
  std::int64_t deletions = 0;
};

struct RobotInfo {
  std::string name;
  std::int64_t scans = 0;
  std::int64_t sessions = 0;
};

struct SessionInfo {
  std::string robot;
  std::string name;
  std::int64_t scans = 0;
  std::int64_t first_seq = 0;
  std::int64_t last_seq = 0;
};

// A scan to store. The fingerprint is stored serialised; its descriptor goes to the index.
struct NewScan {
  std::string map;
  std::string robot;
  std::string session;
  std::int64_t seq = 0;                // sequence number within the session (unique there)
  std::optional<double> stamp;         // seconds, caller's clock
  std::optional<Mat4d> odometry_pose;  // the robot's pose in its session frame
  const Fingerprint* fingerprint = nullptr;
  const LabelledScan* raw = nullptr;  // also keep the raw cloud (off by default: it is ~1.9 MB per scan)
};

struct ScanInfo {
  std::int64_t id = 0;
  std::string map;
  std::string robot;
  std::string session;
  std::int64_t seq = 0;
  std::optional<double> stamp;
  std::optional<Mat4d> odometry_pose;
  std::int64_t fingerprint_bytes = 0;
  bool has_raw = false;
};

struct SearchRequest {
  std::string map;
  std::vector<float> descriptor;
  int k = 50;
  std::vector<std::string> robots;  // only these robots (empty: all)
  std::vector<std::string> exclude_robots;
  std::vector<std::string> sessions;  // only these sessions, as "robot/session" (split at the first '/')
  std::vector<std::pair<std::string, std::string>> session_refs;  // and these (robot, session) (both empty: all)
  // Exclusion of the querying robot's own recent scans: scans of `self_robot` whose seq is within
  // `exclude_recent` of `self_seq` in the same session, or whose stamp is within `exclude_seconds` of
  // `self_stamp` (any session of that robot).
  std::string self_robot;
  std::string self_session;
  std::int64_t self_seq = 0;
  std::int64_t exclude_recent = 0;
  std::optional<double> self_stamp;
  double exclude_seconds = 0;
  std::vector<std::int64_t> exclude_scan_ids;  // e.g. the query scan itself
};

struct SearchHit {
  std::int64_t scan_id = 0;
  float distance = 0;  // L2 distance between descriptors
};

// A verified loop kept for the pose graph. T maps the candidate scan's points into the query scan's frame.
struct LoopRecord {
  std::int64_t id = 0;  // assigned by addLoop
  std::int64_t query_scan = 0;
  std::int64_t candidate_scan = 0;
  Mat4d T = Mat4d::Identity();
  double score = 0, fitness = 0, rmse = 0;
  int inliers = 0;
  // Information of T (sglc::LoopResult::information); absent for loops recorded without one.
  std::optional<Mat6d> information;
  // The loop model's probability that the loop is true (sglc::LoopResult::probability), in [0, 1]; absent for
  // loops recorded before the model (unknown; the pose graph then treats the loop as it always did).
  std::optional<double> probability;
};

// A scan as a pose-graph node.
struct GraphNodeRecord {
  std::int64_t scan_id = 0;
  std::int64_t session_id = 0;
  std::string robot, session;
  std::int64_t seq = 0;
  std::optional<double> stamp;
  std::optional<Mat4d> odometry_pose;
};

// Where a session's odometry frame sits in the map frame (after optimisation).
struct SessionFrame {
  std::int64_t session_id = 0;
  std::string robot, session;
  Mat4d T_map_session = Mat4d::Identity();
  bool connected = false;  // linked to the map frame by loops (else T is its own frame: identity)
};

struct OptimisedPose {
  std::int64_t scan_id = 0;
  Mat4d pose = Mat4d::Identity();  // scan (LiDAR) -> map frame
};

// A scan's place in a lifelong map (docs/LIFELONG.md): the keyframes that verified loops tie together within
// map.place_radius_m share a place, named by the id of the scan that founded it. A kept scan is one of the
// place's long-term versions; the others stay with their session until it ends and is retired.
struct PlaceRecord {
  std::int64_t scan_id = 0;
  std::int64_t place_id = 0;
  bool kept = true;
  // Read back only (places()): the scan's session and seq, and when it was stored (server clock, seconds).
  std::int64_t session_id = 0;
  std::int64_t seq = 0;
  double added_at = 0;
};

// What retireScans did.
struct Retired {
  std::int64_t scans = 0;       // removed from the index and the database
  std::int64_t bytes = 0;       // their fingerprint bytes
  std::int64_t loops_kept = 0;  // loops added in place of loops that touched them
};

struct Stats {
  std::int64_t maps = 0, robots = 0, sessions = 0, scans = 0;
  // Lifelong maps: places, their long-term versions (kept scans), scans retired so far and their fingerprint
  // bytes (the bytes saved), counted since the map's creation.
  std::int64_t places = 0, versions = 0, retired_scans = 0, retired_bytes = 0;
  std::int64_t index_entries = 0;
  std::int64_t db_bytes = 0;
  std::int64_t fingerprint_bytes = 0;
  double cache_mb = 0;
  std::int64_t cache_hits = 0, cache_misses = 0;
};

class MapStore {
 public:
  // Opens or creates the database. Throws StorageError (kCorrupt for a foreign or damaged file,
  // kNewerSchema, kReadOnly, kIo, ...); a failed open leaves the file as it was.
  static std::unique_ptr<MapStore> open(const StoreOptions& options);
  virtual ~MapStore() = default;

  // Maps. createMap is idempotent for an existing map with the same dimension.
  virtual MapInfo createMap(const std::string& name, int descriptor_dim) = 0;
  virtual std::vector<MapInfo> listMaps() const = 0;
  virtual std::optional<MapInfo> findMap(const std::string& name) const = 0;
  virtual std::vector<RobotInfo> listRobots(const std::string& map) const = 0;
  virtual std::vector<SessionInfo> listSessions(const std::string& map, const std::string& robot = "") const = 0;

  // The fingerprint settings recorded for `map` (kNotFound for an unknown map): those of the store that created
  // it, or that recordSettings gave it; nullopt while it has none. kCorrupt when the recorded values do not
  // match their recorded hash. Read from the database on every call: callers cache it (it never changes once
  // recorded; a map deleted and created again has a new id).
  virtual std::optional<FingerprintSettings> mapSettings(const std::string& map) const = 0;
  // Records StoreOptions::settings for `map` (every map when empty; kNotFound for an unknown name) if it has
  // none yet: maps created before settings were recorded (SQLite schema < 7, PostgreSQL schema < 3), or by a
  // store without settings. Returns the names of the maps that got them, in name order; nothing when
  // StoreOptions::settings is empty. Concurrent callers (replicas) record each map once.
  virtual std::vector<std::string> recordSettings(const std::string& map = "") = 0;

  // Stores a scan (robot and session are created on first use) and returns its id once it is durable
  // (per StoreOptions::sync). All or nothing.
  virtual std::int64_t addScan(const NewScan& scan) = 0;

  virtual std::vector<SearchHit> search(const SearchRequest& request) const = 0;
  virtual std::optional<ScanInfo> scanInfo(std::int64_t scan_id) const = 0;
  // The fingerprint of a stored scan, from the cache or the database. nullptr if no such scan.
  virtual std::shared_ptr<const Fingerprint> fingerprint(std::int64_t scan_id) const = 0;
  // The view context of a stored scan for `config` (viewContextOf of its fingerprint), kept apart from the
  // fingerprint cache (about 1 KB a scan, in an eighth of cache_mb more): ranking a map larger than the cache
  // by view reads no fingerprint twice. nullptr if no such scan.
  virtual std::shared_ptr<const ViewContext> viewContext(std::int64_t scan_id,
                                                         const ViewSearchConfig& config) const = 0;
  virtual std::optional<LabelledScan> rawScan(std::int64_t scan_id) const = 0;
  // The scan of (map, robot, session, seq), if stored.
  virtual std::optional<std::int64_t> findScan(const std::string& map, const std::string& robot,
                                               const std::string& session, std::int64_t seq) const = 0;
  // The session's stored scan with the largest seq below `seq`, if any (the scan before it in the robot's run).
  virtual std::optional<std::int64_t> previousScan(const std::string& map, const std::string& robot,
                                                   const std::string& session, std::int64_t seq) const = 0;

  // Deletions remove scans from the index and the database together. Return the number of scans removed.
  virtual std::int64_t deleteSession(const std::string& map, const std::string& robot, const std::string& session) = 0;
  virtual std::int64_t deleteRobot(const std::string& map, const std::string& robot) = 0;
  // The whole map (scans, robots, sessions, loops, poses, its index); kNotFound for an unknown map. Returns the
  // number of scans removed. A map of the same name created afterwards starts empty.
  virtual std::int64_t deleteMap(const std::string& map) = 0;

  // Online backup of the live database to a new file (VACUUM INTO). Fails if dest exists.
  virtual void backup(const std::string& dest) const = 0;
  // "ok", or SQLite's description of the damage.
  virtual std::string integrityCheck() const = 0;
  virtual Stats stats(const std::string& map = "") const = 0;
  // Writes index snapshots now (also done on destruction when enabled).
  virtual void snapshot() = 0;

  // ---- Pose graph (loops, optimised poses, session frames), kept with the map.
  // Records a loop between two scans of the map; a second loop for the same (query, candidate) replaces the
  // first. Returns its id. kNotFound for a scan that is not in the map, kInvalidArgument for a non-finite T.
  virtual std::int64_t addLoop(const std::string& map, const LoopRecord& loop) = 0;
  // Loops with id > after_id, in id order; at most `limit` of them (0: all).
  virtual std::vector<LoopRecord> loops(const std::string& map, std::int64_t after_id = 0,
                                        std::int64_t limit = 0) const = 0;
  // Scans with id > after_scan, in id order.
  virtual std::vector<GraphNodeRecord> graphNodes(const std::string& map, std::int64_t after_scan = 0) const = 0;
  // Replaces the optimised poses of the given scans and the given sessions' frames in one transaction and
  // bumps the map's graph version, which it returns. `map_id` is the MapInfo::id the poses were computed for:
  // when the map was deleted meanwhile, or deleted and its name created again (ids are never reused), nothing
  // is written (kNotFound). `through_loop` is the id of the last loop the poses account for (see
  // optimisedThroughLoop). Scans or sessions deleted meanwhile are skipped.
  virtual std::int64_t saveOptimised(const std::string& map, std::int64_t map_id,
                                     const std::vector<OptimisedPose>& poses, const std::vector<SessionFrame>& frames,
                                     std::int64_t through_loop) = 0;
  // Optimised poses in scan-id order: of one robot (and session) or the whole map (empty names), scan ids
  // > after_scan, at most `limit`.
  virtual std::vector<OptimisedPose> optimisedPoses(const std::string& map, const std::string& robot,
                                                    const std::string& session, std::int64_t after_scan,
                                                    std::int64_t limit) const = 0;
  virtual std::vector<SessionFrame> sessionFrames(const std::string& map) const = 0;
  // 0 until the first saveOptimised; survives restarts.
  virtual std::int64_t graphVersion(const std::string& map) const = 0;
  // The through_loop of the last saveOptimised (0 before any, or in files from before schema 4): loops with
  // larger ids are not yet reflected in the stored poses.
  virtual std::int64_t optimisedThroughLoop(const std::string& map) const = 0;

  // ---- Lifelong maps: places and retirement (docs/LIFELONG.md).
  // Records (or replaces) the places of scans of `map`, in one transaction. kNotFound for a scan not in the map.
  virtual void setPlaces(const std::string& map, const std::vector<PlaceRecord>& records) = 0;
  // Every placed scan of `map`, in scan-id order, with its session, seq and time of storage.
  virtual std::vector<PlaceRecord> places(const std::string& map) const = 0;
  // The place of one scan, if it has one.
  virtual std::optional<PlaceRecord> placeOf(std::int64_t scan_id) const = 0;
  // The number of kept versions of place `place_id` of `map`.
  virtual std::int64_t placeVersions(const std::string& map, std::int64_t place_id) const = 0;
  // Retires scans of `map` in one transaction: they leave the index and the database with everything that hangs
  // on them (as deletions do: loops, optimised poses, places), and `new_loops` (between scans that stay: the
  // retired scans' loops moved to them) are added unless a loop of the same pair exists. Counts into the map's
  // retired totals; bumps MapInfo::deletions (pose graphs rebuild). Scans already gone are skipped. Serialised
  // with every other write (PostgreSQL: the database-wide write lock, across processes).
  virtual Retired retireScans(const std::string& map, const std::vector<std::int64_t>& scans,
                              const std::vector<LoopRecord>& new_loops) = 0;

  // ---- Several processes on one database (PostgreSQL): who solves a map's pose graph.
  // True when other processes may write this database too (their scans and loops appear without a call here).
  virtual bool shared() const { return false; }
  // Whether this process holds the right to solve the pose graph of map `map_id`, taking it when free. One
  // process holds it at a time; it goes with the process (or its database connection), so another takes it
  // over when the holder dies. kTaken: taken by this call (what this process knew of the graph may be stale:
  // another process may have solved it meanwhile); kHeld: held since the last claim; kElsewhere: another process
  // holds it, or the database cannot be reached. Always kHeld for a store that is not shared.
  enum class GraphClaim { kElsewhere, kTaken, kHeld };
  virtual GraphClaim claimGraph(std::int64_t /*map_id*/) { return GraphClaim::kHeld; }
};

// True when `path` names a PostgreSQL database (postgresql://... or postgres://...) rather than a SQLite file.
bool isPostgresUrl(const std::string& path);
// `path` as logs may show it: a PostgreSQL URL's password replaced by ***.
std::string printableLocation(const std::string& path);

// Schema version this build writes; older files are migrated forward on open.
inline constexpr int kSchemaVersion = 9;

}  // namespace sglc::storage
