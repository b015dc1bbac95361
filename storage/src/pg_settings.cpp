// Each map's fingerprint settings in the PostgreSQL map database: the SQLite store's layout (map_settings.hpp).
#include "map_settings.hpp"
#include "pg_parts.hpp"

namespace sglc::storage::pg::settings {

using Code = StorageError::Code;

void write(const Conn& db, std::int64_t map_id, const FingerprintSettings& settings) {
  if (settings.empty()) return;
  db.query("UPDATE maps SET settings_hash = $1 WHERE id = $2", {settings.hash, map_id});
  std::int64_t position = 0;
  for (const auto& [key, value] : settings.values)
    db.query("INSERT INTO map_settings(map_id, position, key, value) VALUES($1, $2, $3, $4)",
             {map_id, position++, key, value});
}

std::optional<FingerprintSettings> read(const Core& core, const std::string& map) {
  const auto map_id = core.mapId(map);
  auto db = core.readers.acquire();
  const auto h = db->query("SELECT settings_hash FROM maps WHERE id = $1", {map_id});
  if (h.rows() == 0) throw StorageError(Code::kNotFound, "no map named '" + map + "'");  // deleted meanwhile
  if (h.isNull(0, 0)) return std::nullopt;
  const auto r = db->query("SELECT key, value FROM map_settings WHERE map_id = $1 ORDER BY position", {map_id});
  std::vector<Setting> values;
  for (int i = 0; i < r.rows(); ++i) values.emplace_back(r.text(i, 0), r.text(i, 1));
  return map_settings::checked(map, h.text(0, 0), std::move(values));
}

std::vector<std::string> recordMissing(Core& core, const std::string& map) {
  const auto& settings = core.options.settings;
  if (!map.empty()) core.mapId(map);  // kNotFound
  if (settings.empty()) return {};
  // Under the database-wide write lock: replicas opening together record each map once, the first one's.
  WriteTx tx(core);
  const auto r = tx.conn().query(
      "SELECT id, name FROM maps WHERE settings_hash IS NULL AND ($1 = '' OR name = $1) ORDER BY name COLLATE \"C\"",
      {map});
  std::vector<std::string> names;
  for (int i = 0; i < r.rows(); ++i) {
    write(tx.conn(), r.i64(i, 0), settings);
    names.push_back(r.text(i, 1));
  }
  tx.commit(0, [] {});  // no journal entry: no catalogue holds settings
  return names;
}

}  // namespace sglc::storage::pg::settings
