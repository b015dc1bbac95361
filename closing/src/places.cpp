#include "sglc/closing/places.hpp"

#include <tuple>

namespace sglc::closing {
namespace {

using namespace params;

#define SGLC_KEY(name) \
#name, [](auto& o) -> auto& { return o.name; }

Table<LifelongOptions> makeTable() {
  Table<LifelongOptions> t;
  t.add(field<LifelongOptions>(SGLC_KEY(max_versions_per_place), closed(0, 1000),
                               "lifelong maps: versions kept per place; a scan that relocalizes into a place that has "
                               "them all is answered and joins its session's graph, then retires with the session "
                               "(0: off, every scan kept)"));
  t.add(field<LifelongOptions>(
      SGLC_KEY(place_radius_m), above(0),
      "lifelong maps: a verified loop to a scan this close (m) puts a scan in that scan's place"));
  t.add(field<LifelongOptions>(SGLC_KEY(min_probability), closed(0, 1),
                               "lifelong maps: the loop model's probability such a loop needs"));
  t.add(field<LifelongOptions>(SGLC_KEY(session_retention_h), closed(0, 87600),
                               "lifelong maps: a session's scans that are not versions of their places are retired "
                               "this long after its last scan (h; it must exceed the longest pause within a drive)"));
  t.add(field<LifelongOptions>(SGLC_KEY(max_moved_loops_per_scan), closed(0, 1000),
                               "lifelong maps: a retired scan's loops move to the nearest scans of its session that "
                               "stay; each of those takes them while it has fewer loops than this, the ones moved "
                               "the least first"));
  t.add(field<LifelongOptions>(SGLC_KEY(compact_interval_s), closed(0, 604800),
                               "lifelong maps: the server compacts every map this often (s; 0: only sglc compact "
                               "does; nothing runs with the policy off)"));
  return t;
}

#undef SGLC_KEY

}  // namespace

const params::Table<LifelongOptions>& lifelongParams() {
  static const params::Table<LifelongOptions> table = makeTable();
  return table;
}

std::vector<storage::PlaceRecord> placeScan(std::int64_t scan_id, const std::vector<PlaceTie>& ties,
                                            const LifelongOptions& options, const PlaceLookup& lookup) {
  const PlaceTie* best = nullptr;
  for (const auto& t : ties) {
    if (!t.probability || *t.probability < options.min_probability || t.distance_m > options.place_radius_m ||
        t.candidate_scan == scan_id)
      continue;
    if (!best || std::make_tuple(-*t.probability, t.distance_m, t.candidate_scan) <
                     std::make_tuple(-*best->probability, best->distance_m, best->candidate_scan))
      best = &t;
  }
  std::vector<storage::PlaceRecord> out;
  if (!best) {
    out.push_back({scan_id, scan_id, true});
    return out;
  }
  std::int64_t place = best->candidate_scan;
  if (const auto p = lookup.place_of(best->candidate_scan))
    place = p->place_id;
  else
    out.push_back({best->candidate_scan, best->candidate_scan, true});  // founds the place it now shares
  const auto kept = lookup.versions(place) + static_cast<std::int64_t>(out.size());
  out.push_back({scan_id, place, options.max_versions_per_place <= 0 || kept < options.max_versions_per_place});
  return out;
}

}  // namespace sglc::closing
