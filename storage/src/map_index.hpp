// Each map's descriptor index as the store keeps it: loaded from its snapshot or rebuilt from the scans on
// open, searched with the catalogue's names turned into filters, and snapshotted on close.
#pragma once

#include <vector>

#include "store_core.hpp"

namespace sglc::storage::map_index {

// Fills m's index from its snapshot when one of m's generation exists (and snapshots are on), else from the
// scan rows. Called while opening, before any other thread sees the store.
void load(StoreCore& core, MapState& m);
std::vector<SearchHit> search(const StoreCore& core, const SearchRequest& request);
// The search of one map's index (the caller holds the lock that guards it): checks the request, turns its
// names into the map's ids, searches.
std::vector<SearchHit> searchMap(const MapState& m, const SearchRequest& request);
// Writes every map's snapshot; a map with deletions since its index was built gets none (the next open
// rebuilds it without the deleted scans).
void snapshot(StoreCore& core);
// Removes the snapshot of a deleted map (best effort: a failure only leaves a file whose id no longer matches,
// as long as no new map gets the id; the removal is logged by the caller's result, not thrown).
void removeSnapshot(const StoreCore& core, std::int64_t map_id);

}  // namespace sglc::storage::map_index
