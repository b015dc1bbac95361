// The PostgreSQL map store, selected by a postgresql:// URL as StoreOptions::path.
#pragma once

#include <memory>

#include "sglc/storage/map_store.hpp"

namespace sglc::storage::pg {

// Connects, creates or migrates the schema, loads the catalogue and indexes, and starts following other
// processes' writes. Throws StorageError (kUnavailable when the server cannot be reached, kCorrupt for a
// database of another application, kNewerSchema, kInvalidArgument for a bad URL).
std::unique_ptr<MapStore> open(const StoreOptions& options);

}  // namespace sglc::storage::pg
