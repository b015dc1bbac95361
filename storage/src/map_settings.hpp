// Each map's fingerprint settings (sglc/fingerprint_settings.hpp) in the SQLite map database: written with the
// map, read when a server checks that it may use the map, given to maps that have none. The layout, the same in
// PostgreSQL (pg_settings.cpp): maps.settings_hash (NULL: none recorded) and one row per setting in
// map_settings(map_id, position, key, value), deleted with the map (ON DELETE CASCADE).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "sglc/fingerprint_settings.hpp"
#include "store_core.hpp"

namespace sglc::storage::map_settings {

// Writes `settings` for map `map_id` in the caller's transaction on `db` (nothing for empty settings).
void write(const sql::Db& db, std::int64_t map_id, const FingerprintSettings& settings);

// MapStore::mapSettings and MapStore::recordSettings.
std::optional<FingerprintSettings> read(const StoreCore& core, const std::string& map);
std::vector<std::string> recordMissing(StoreCore& core, const std::string& map);

// Settings read back from `map`'s rows; kCorrupt when `hash` is not theirs (both back-ends).
FingerprintSettings checked(const std::string& map, std::string hash, std::vector<Setting> values);

}  // namespace sglc::storage::map_settings
