// The parts of the PostgreSQL map store (pg_map_store.cpp forwards to them), one file each: scans and their
// blobs, the pose-graph tables, administration, each map's fingerprint settings.
#pragma once

#include <string>
#include <vector>

#include "pg_core.hpp"

namespace sglc::storage::pg {

namespace scans {
std::int64_t add(Core& core, const NewScan& scan);
std::optional<ScanInfo> info(const Core& core, std::int64_t scan_id);
std::shared_ptr<const Fingerprint> fingerprint(const Core& core, std::int64_t scan_id);
std::optional<LabelledScan> raw(const Core& core, std::int64_t scan_id);
// The scan of the session with exactly `seq`, or the one with the largest seq below it.
enum class SeqMatch { kExact, kLatestBefore };
std::optional<std::int64_t> find(const Core& core, const std::string& map, const std::string& robot,
                                 const std::string& session, std::int64_t seq, SeqMatch match = SeqMatch::kExact);
std::int64_t deleteSession(Core& core, const std::string& map, const std::string& robot, const std::string& session);
std::int64_t deleteRobot(Core& core, const std::string& map, const std::string& robot);
std::int64_t deleteMap(Core& core, const std::string& map);
}  // namespace scans

namespace graph {
std::int64_t addLoop(Core& core, const std::string& map, const LoopRecord& loop);
std::vector<LoopRecord> loops(const Core& core, const std::string& map, std::int64_t after_id, std::int64_t limit);
std::vector<GraphNodeRecord> nodes(const Core& core, const std::string& map, std::int64_t after_scan);
std::int64_t saveOptimised(Core& core, const std::string& map, std::int64_t map_id,
                           const std::vector<OptimisedPose>& poses, const std::vector<SessionFrame>& frames,
                           std::int64_t through_loop);
std::vector<OptimisedPose> optimisedPoses(const Core& core, const std::string& map, const std::string& robot,
                                          const std::string& session, std::int64_t after_scan, std::int64_t limit);
std::vector<SessionFrame> sessionFrames(const Core& core, const std::string& map);
std::int64_t mapValue(const Core& core, const std::string& map, const char* column_query);
}  // namespace graph

namespace places {
void set(Core& core, const std::string& map, const std::vector<PlaceRecord>& records);
std::vector<PlaceRecord> all(const Core& core, const std::string& map);
std::optional<PlaceRecord> of(const Core& core, std::int64_t scan_id);
std::int64_t versions(const Core& core, const std::string& map, std::int64_t place_id);
Retired retire(Core& core, const std::string& map, const std::vector<std::int64_t>& scans,
               const std::vector<LoopRecord>& new_loops);
// The places, kept versions and retired totals of one map (map_id) or all (map_id < 0), into `s`.
void count(const Conn& db, std::int64_t map_id, Stats& s);
}  // namespace places

namespace admin {
// pg_dump (custom format) of the database into `dest`, which must not exist.
void backup(const Core& core, const std::string& dest);
// "ok", or one line per inconsistency found.
std::string integrityCheck(const Core& core);
Stats stats(const Core& core, const std::string& map);
// Bytes our tables take (heap, TOAST and indexes).
std::int64_t databaseBytes(const Conn& conn);
}  // namespace admin

namespace settings {
// Writes `settings` for map `map_id` in the caller's transaction on `db` (nothing for empty settings).
void write(const Conn& db, std::int64_t map_id, const FingerprintSettings& settings);
// MapStore::mapSettings and MapStore::recordSettings.
std::optional<FingerprintSettings> read(const Core& core, const std::string& map);
std::vector<std::string> recordMissing(Core& core, const std::string& map);
}  // namespace settings

}  // namespace sglc::storage::pg
