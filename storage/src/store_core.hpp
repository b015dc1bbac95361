// What the parts of the SQLite map store share: the database, the catalogue with the descriptor indexes, the
// fingerprint cache, and the locking discipline.
//
// Writers take write_mutex (one at a time), do their SQL in a transaction while readers go on, and take
// state_mutex exclusively only around the commit and the matching catalogue/index update, so no reader sees
// one without the other. Readers take state_mutex shared and a pooled read-only connection.
#pragma once

#include <mutex>
#include <string>

#include "catalogue.hpp"
#include "fair_shared_mutex.hpp"
#include "fingerprint_cache.hpp"
#include "reader_pool.hpp"
#include "schema.hpp"

namespace sglc::storage {

struct StoreCore {
  explicit StoreCore(const StoreOptions& options);

  const sql::Db& writer() const { return db.writer; }
  // The id of `map` (kNotFound), under a shared lock of its own.
  std::int64_t mapId(const std::string& map) const;

  const StoreOptions options;
  OpenedDatabase db;
  ReaderPool readers;
  mutable std::mutex write_mutex;
  mutable FairSharedMutex state_mutex;  // catalogue + indexes
  Catalogue catalogue;
  mutable FingerprintCache cache;
};

}  // namespace sglc::storage
