// Compaction of a lifelong map (docs/LIFELONG.md): places for the scans that have none (maps built before the
// policy, or scans stored without a query), each place's versions chosen (closing/versions.hpp), then the
// retirement of the scans of ended sessions that are not versions of their places, with their loops moved to the
// scans of their sessions that stay.
#pragma once

#include <cstdint>
#include <string>

#include "sglc/closing/places.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::closing {

// The odometry noise the pose graph assumes (pose_graph.odometry_sigma_*): a loop moved from a retired scan to
// a scan of its session that stays carries the odometry between the two as added uncertainty.
struct OdometryNoise {
  double sigma_m = 0.01, sigma_per_m = 0.015, sigma_deg = 0.005, sigma_deg_per_m = 0.005;
};

struct CompactionReport {
  std::int64_t placed = 0;                // scans given a place
  std::int64_t promoted = 0;              // surplus scans made versions (too few, or replacing an unused one)
  std::int64_t demoted = 0;               // versions made surplus (too many, or replaced)
  std::int64_t retired = 0;               // scans retired
  std::int64_t retired_bytes = 0;         // their fingerprint bytes
  std::int64_t loops_moved = 0;           // loops recorded between scans that stay in place of retired scans' loops
  std::int64_t loops_dropped = 0;         // retired scans' loops with no scan of the session left to carry them
  std::int64_t open_sessions = 0;         // sessions left whole: their last scan is within the retention
  std::int64_t places = 0, versions = 0;  // after compaction
};

// Applies the policy to `map` at time `now_s` (server clock, seconds; scans' time of storage is compared with
// it). Places are assigned with the policy's rule even when it is off; nothing is retired then. Retirement is
// one transaction of the store: a crash leaves the map as it was before or after.
CompactionReport compact(storage::MapStore& store, const std::string& map, const LifelongOptions& options,
                         const OdometryNoise& noise, double now_s);

}  // namespace sglc::closing
