// Places of lifelong maps (docs/LIFELONG.md) in the SQLite store: which place each scan belongs to and whether
// it is one of the place's kept versions, and the retirement of scans with their loops moved to scans that stay.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "store_core.hpp"

namespace sglc::storage::places_table {

void set(StoreCore& core, const std::string& map, const std::vector<PlaceRecord>& records);
std::vector<PlaceRecord> all(const StoreCore& core, const std::string& map);
std::optional<PlaceRecord> of(const StoreCore& core, std::int64_t scan_id);
std::int64_t versions(const StoreCore& core, const std::string& map, std::int64_t place_id);
Retired retire(StoreCore& core, const std::string& map, const std::vector<std::int64_t>& scans,
               const std::vector<LoopRecord>& new_loops);
// The places, kept versions and retired totals of one map (map_id) or all (map_id < 0), into `s`.
void count(const sql::Db& db, std::int64_t map_id, Stats& s);

}  // namespace sglc::storage::places_table
