#include "sglc/storage/store_params.hpp"

namespace sglc::storage {
namespace {

using namespace params;
using Sync = StoreOptions::Sync;
using IndexType = IndexOptions::Type;

Table<StoreOptions> makeTable() {
  Table<StoreOptions> t;
  t.add(choice<StoreOptions>(
      "sync", [](auto& o) -> auto& { return o.sync; },
      std::vector<std::pair<std::string, Sync>>{{"full", Sync::kFull}, {"normal", Sync::kNormal}, {"off", Sync::kOff}},
      "SQLite synchronous mode: full survives power loss, normal only process crashes"));
  t.add(field<StoreOptions>(
      "cache_mb", [](auto& o) -> auto& { return o.cache_mb; }, closed(0, 1e9),
      "decoded fingerprints kept in memory (MB, least recently used evicted); stored scans' view contexts get an "
      "eighth of it more (at least 4 MB, none at 0)"));
  t.add(field<StoreOptions>(
      "busy_timeout_ms", [](auto& o) -> auto& { return o.busy_timeout_ms; }, atLeast(0),
      "wait this long for a lock another connection holds (ms)"));
  t.add(field<StoreOptions>(
      "stall_timeout_ms", [](auto& o) -> auto& { return o.stall_timeout_ms; }, atLeast(0),
      "PostgreSQL: a replica stopped this long (frozen, paused) inside a write loses it and the write lock, and "
      "loses its maps' pose graphs to the other replicas (ms; 0: never)"));
  t.add(field<StoreOptions>(
      "snapshot_index", [](auto& o) -> auto& { return o.snapshot_index; }, {},
      "save the FAISS indexes beside the database on close, load them on open"));
  t.add(field<StoreOptions>(
      "max_db_mb", [](auto& o) -> auto& { return o.max_db_mb; }, closed(0, 1e9),
      "quota: writes beyond it fail with RESOURCE_EXHAUSTED (MB; 0: unlimited)"));
  t.add(choice<StoreOptions>(
      "index", [](auto& o) -> auto& { return o.index.type; },
      std::vector<std::pair<std::string, IndexType>>{{"exact", IndexType::kExact}, {"ivf", IndexType::kIvf}},
      "descriptor search: exact (flat L2) or ivf (approximate, for millions of scans)"));
  t.add(field<StoreOptions>(
      "ivf_nlist", [](auto& o) -> auto& { return o.index.ivf_nlist; }, atLeast(0), "IVF cells (0: about sqrt(scans))"));
  t.add(field<StoreOptions>(
      "ivf_nprobe", [](auto& o) -> auto& { return o.index.ivf_nprobe; }, atLeast(1), "IVF cells visited per search"));
  t.add(field<StoreOptions>(
      "ivf_min_scans", [](auto& o) -> auto& { return o.index.ivf_min_scans; }, atLeast(0),
      "an IVF map with fewer scans is searched exactly (training needs data)"));
  return t;
}

}  // namespace

const params::Table<StoreOptions>& storeParams() {
  static const params::Table<StoreOptions> table = makeTable();
  return table;
}

}  // namespace sglc::storage
