// Each map's fingerprint settings in the SQLite map database (map_settings.hpp).
#include "map_settings.hpp"

#include <mutex>
#include <shared_mutex>

namespace sglc::storage::map_settings {

using Code = StorageError::Code;

void write(const sql::Db& db, std::int64_t map_id, const FingerprintSettings& settings) {
  if (settings.empty()) return;
  sql::Stmt(db, "UPDATE maps SET settings_hash = ? WHERE id = ?").bind(1, settings.hash).bind(2, map_id).run();
  sql::Stmt row(db, "INSERT INTO map_settings(map_id, position, key, value) VALUES(?, ?, ?, ?)");
  std::int64_t position = 0;
  for (const auto& [key, value] : settings.values) {
    row.reset();
    row.bind(1, map_id).bind(2, position++).bind(3, key).bind(4, value).run();
  }
}

FingerprintSettings checked(const std::string& map, std::string hash, std::vector<Setting> values) {
  FingerprintSettings s{std::move(values), std::move(hash)};
  if (s.values.empty() || settingsHash(s.values) != s.hash)
    throw StorageError(Code::kCorrupt, "map '" + map + "': its recorded fingerprint settings do not match their hash");
  return s;
}

std::optional<FingerprintSettings> read(const StoreCore& core, const std::string& map) {
  const auto map_id = core.mapId(map);
  auto reader = core.readers.acquire();
  std::string hash;
  {
    sql::Stmt st(*reader, "SELECT settings_hash FROM maps WHERE id = ?");
    st.bind(1, map_id);
    if (!st.step()) throw StorageError(Code::kNotFound, "no map named '" + map + "'");  // deleted meanwhile
    if (st.isNull(0)) return std::nullopt;
    hash = st.text(0);
  }
  std::vector<Setting> values;
  sql::Stmt st(*reader, "SELECT key, value FROM map_settings WHERE map_id = ? ORDER BY position");
  st.bind(1, map_id);
  while (st.step()) values.emplace_back(st.text(0), st.text(1));
  return checked(map, std::move(hash), std::move(values));
}

std::vector<std::string> recordMissing(StoreCore& core, const std::string& map) {
  const auto& settings = core.options.settings;
  if (!map.empty()) core.mapId(map);  // kNotFound
  if (settings.empty()) return {};
  std::lock_guard write_lock(core.write_mutex);
  const auto& db = core.writer();
  sql::Transaction tx(db);
  std::vector<std::pair<std::int64_t, std::string>> missing;
  {
    sql::Stmt st(db, "SELECT id, name FROM maps WHERE settings_hash IS NULL AND (? = '' OR name = ?) ORDER BY name");
    st.bind(1, map).bind(2, map);
    while (st.step()) missing.emplace_back(st.i64(0), st.text(1));
  }
  std::vector<std::string> names;
  for (const auto& [id, name] : missing) {
    write(db, id, settings);
    names.push_back(name);
  }
  tx.commit();  // the catalogue does not hold settings: nothing to change under the state lock
  return names;
}

}  // namespace sglc::storage::map_settings
