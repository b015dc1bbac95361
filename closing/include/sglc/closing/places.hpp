// Places of a lifelong map (docs/LIFELONG.md): the rule that puts a newly stored scan in a place, and the
// settings of the policy that bounds how many versions of a place the map keeps.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "sglc/params.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::closing {

struct LifelongOptions {
  // Versions (kept scans) per place; 0: the policy is off and every scan is kept for ever.
  int max_versions_per_place = 0;
  // A verified loop ties a scan to its candidate's place when the candidate is at most this far (m).
  double place_radius_m = 3.0;
  // ... and the loop model is at least this sure of the loop.
  double min_probability = 0.9;
  // A session's scans that are not versions of their places are retired this long after its last scan (h).
  double session_retention_h = 24.0;
  // A retired scan's loops move to the nearest scans of its session that stay; each of those takes them while it
  // has fewer loops in all than this (its own and those moved before), the ones moved the least first.
  int max_moved_loops_per_scan = 4;
  // The server compacts every map this often (s; 0: only `sglc compact` does).
  double compact_interval_s = 600.0;

  bool enabled() const { return max_versions_per_place > 0; }
};

// The `map` settings table (server config section `map`).
const params::Table<LifelongOptions>& lifelongParams();

// A verified loop of a scan, as the place rule reads it.
struct PlaceTie {
  std::int64_t candidate_scan = 0;
  std::optional<double> probability;  // absent: loops recorded before the loop model, never a tie
  double distance_m = 0;              // between the two scans (|translation| of the loop's pose)
};

// What the rule needs of the map: a scan's place (nullopt when it has none yet) and a place's kept versions.
struct PlaceLookup {
  std::function<std::optional<storage::PlaceRecord>(std::int64_t scan_id)> place_of;
  std::function<std::int64_t(std::int64_t place_id)> versions;
};

// The place of scan `scan_id` given its verified loops: the place of the candidate of its surest tie (probability
// >= min_probability, candidate within place_radius_m; ties broken by the nearer candidate, then the lower id),
// kept as a version while the place has fewer than max_versions_per_place; with no such tie, a new place it
// founds (named by its id) and keeps. A candidate without a place yet founds its own (its record is returned
// first). Deterministic in its inputs.
std::vector<storage::PlaceRecord> placeScan(std::int64_t scan_id, const std::vector<PlaceTie>& ties,
                                            const LifelongOptions& options, const PlaceLookup& lookup);

}  // namespace sglc::closing
