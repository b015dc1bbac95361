#include "admin.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "places_table.hpp"
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
  const auto map_id = core.catalogue.count(map, s);
  sql::Stmt st(*reader, "SELECT count(*), coalesce(sum(fingerprint_bytes), 0) FROM scans WHERE ? < 0 OR map_id = ?");
  st.bind(1, map_id).bind(2, map_id);
  if (st.step()) {
    s.scans = st.i64(0);
    s.fingerprint_bytes = st.i64(1);
  }
  places_table::count(*reader, map_id, s);
  std::error_code ec;
  for (const char* suffix : {"", "-wal"}) {
    const auto size = fs::file_size(core.options.path + suffix, ec);
    if (!ec) s.db_bytes += static_cast<std::int64_t>(size);
  }
  core.cache.report(s);
  return s;
}

}  // namespace sglc::storage::admin
