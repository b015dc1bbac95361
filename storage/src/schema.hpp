// The map database file: opening it safely (one process at a time, ours and not a foreign or newer file),
// its pragmas, and the schema with its forward migrations.
#pragma once

#include <string>

#include "process_lock.hpp"
#include "sglc/storage/map_store.hpp"
#include "sqlite.hpp"

namespace sglc::storage {

struct OpenedDatabase {
  ProcessLock lock;   // before writer: released after the database is closed
  sql::Db writer;     // the one read-write connection (WAL, foreign keys on, options' sync and size cap)
  std::string token;  // random, fixed at creation: names this file's index snapshots
};

// Opens or creates the database at options.path and migrates it to kSchemaVersion, each step in its own
// transaction. Throws StorageError: kInvalidArgument (empty path, a directory), kReadOnly, kBusy (another
// process holds it), kCorrupt (not SQLite, a foreign SQLite file, no token), kNewerSchema, kIo.
OpenedDatabase openDatabase(const StoreOptions& options);

}  // namespace sglc::storage
