#include "admin.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "validate.hpp"

namespace sglc::storage::admin {
namespace {

namespace fs = std::filesystem;
using Code = StorageError::Code;

}  // namespace

void backup(const StoreCore& core, const std::string& dest) {
  validate::claimBackupFile(dest);  // VACUUM INTO accepts an existing empty file
  auto reader = core.readers.acquire();
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

std::string integrityCheck(const StoreCore& core) {
  auto reader = core.readers.acquire();
  sql::Stmt st(*reader, "PRAGMA integrity_check");
  std::string out;
  while (st.step()) out += (out.empty() ? "" : "\n") + st.text(0);
  return out;
}

Stats stats(const StoreCore& core, const std::string& map) {
  std::shared_lock lock(core.state_mutex);
  Stats s;
  auto reader = core.readers.acquire();
  std::int64_t map_id = -1;
  if (!map.empty()) map_id = core.catalogue.map(map).id;
  s.maps = map.empty() ? static_cast<std::int64_t>(core.catalogue.maps().size()) : 1;
  for (const auto& [name, m] : core.catalogue.maps()) {
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
    const auto size = fs::file_size(core.options.path + suffix, ec);
    if (!ec) s.db_bytes += static_cast<std::int64_t>(size);
  }
  s.cache_mb = static_cast<double>(core.cache.usedBytes()) / (1024.0 * 1024.0);
  s.cache_hits = core.cache.hits();
  s.cache_misses = core.cache.misses();
  return s;
}

}  // namespace sglc::storage::admin
