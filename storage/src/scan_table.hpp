// Scans and their blobs: storing a scan (robot and session created on first use), reading its row, its
// fingerprint (through the cache) and its raw cloud, and deleting scans by session or robot with everything
// that hangs on them.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "store_core.hpp"

namespace sglc::storage::scan_table {

std::int64_t add(StoreCore& core, const NewScan& scan);
std::optional<ScanInfo> info(const StoreCore& core, std::int64_t scan_id);
std::shared_ptr<const Fingerprint> fingerprint(const StoreCore& core, std::int64_t scan_id);
std::optional<LabelledScan> raw(const StoreCore& core, std::int64_t scan_id);
// The scan of the session with exactly `seq`, or the one with the largest seq below it.
enum class SeqMatch { kExact, kLatestBefore };
std::optional<std::int64_t> find(const StoreCore& core, const std::string& map, const std::string& robot,
                                 const std::string& session, std::int64_t seq, SeqMatch match = SeqMatch::kExact);

std::int64_t deleteSession(StoreCore& core, const std::string& map, const std::string& robot,
                           const std::string& session);
std::int64_t deleteRobot(StoreCore& core, const std::string& map, const std::string& robot);
// The whole map: its scans with everything that hangs on them, robots, sessions, the map row, its index and its
// index snapshot. Returns the number of scans removed.
std::int64_t deleteMap(StoreCore& core, const std::string& map);

}  // namespace sglc::storage::scan_table
