// Which scans of each place of a lifelong map are its versions (docs/LIFELONG.md, "Which scans a place keeps"):
// the policy's number per place, and a version that none of the latest visits chose gives its slot to the visit's
// scan that served last. Plain data in, plain data out: compaction applies the result.
#pragma once

#include <cstdint>
#include <unordered_set>
#include <vector>

#include "sglc/closing/places.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::closing {

struct VersionChanges {
  std::vector<storage::PlaceRecord> changed;  // the records whose `kept` changed, as they are now
  std::int64_t promoted = 0;                  // surplus scans made versions
  std::int64_t demoted = 0;                   // versions made surplus
};

// Rebalances `places` (the map's records in scan-id order, updated in place) to `options.max_versions_per_place`:
// 1. a place holding more keeps its oldest versions (places assigned with the policy off, or the setting lowered);
// 2. a place holding fewer takes its newest surplus scans (a version's session was deleted, or the setting raised);
// 3. replacement: a scan *serves* when it is stored and whenever a later scan's verified loop chooses it as
//    candidate (`loops`: the query chose the candidate, at the query's storage time). The latest visits are the
//    ended sessions that have surplus scans as the map stands (those since the last compaction). In a place with
//    such surplus scans, a version of an ended session that last served more than `options.session_retention_h`
//    before the first scan of the latest visits was stored (none of them chose it, nor any scan stored within a
//    retention before them) gives its slot to the place's surplus scan that served last (ties:
//    the newer); the versions that served least go first, one per surplus scan, and a session that holds a
//    version of the place takes no slot (so the versions stay from different drives). A place thus keeps the
//    versions the fleet keeps relocalizing into and takes the current look of the place in place of one that no
//    visit chose. Only stored scans' loops count: a Query that is not stored chooses nothing.
// Scans of `open_sessions`, and scans steps 1 and 2 changed, take no part in step 3. Deterministic in its inputs.
VersionChanges rebalanceVersions(std::vector<storage::PlaceRecord>& places,
                                 const std::vector<storage::LoopRecord>& loops, const LifelongOptions& options,
                                 const std::unordered_set<std::int64_t>& open_sessions);

}  // namespace sglc::closing
