#include "sglc/closing/versions.hpp"

#include <algorithm>
#include <map>
#include <optional>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

namespace sglc::closing {
namespace {

using storage::PlaceRecord;

void setKept(PlaceRecord& p, bool kept, VersionChanges& out) {
  p.kept = kept;
  out.changed.push_back(p);
  ++(kept ? out.promoted : out.demoted);
}

// When each scan last served: when it was stored, or when a later scan that verified a loop to it was stored.
std::unordered_map<std::int64_t, double> lastServed(const std::vector<PlaceRecord>& places,
                                                    const std::vector<storage::LoopRecord>& loops) {
  std::unordered_map<std::int64_t, double> stored, served;
  for (const auto& p : places) stored[p.scan_id] = served[p.scan_id] = p.added_at;
  for (const auto& l : loops) {
    const auto q = stored.find(l.query_scan);  // when the query was stored, not when it last served
    const auto c = served.find(l.candidate_scan);
    if (q != stored.end() && c != served.end()) c->second = std::max(c->second, q->second);
  }
  return served;
}

// Step 3 for one place: `versions` and `visits` (its surplus scans of ended sessions) as indexes into `places`;
// a version that last served before `in_use_since` is unused (the first scan of the sessions that left those
// surplus scans, less a retention: a drive whose session is that recent is still in use). A session that
// holds a version of the place (or has just taken one) takes no slot: the versions stay from different drives.
void replaceUnused(std::vector<PlaceRecord>& places, std::vector<std::size_t> versions, std::vector<std::size_t> visits,
                   double in_use_since, const std::unordered_map<std::int64_t, double>& served, VersionChanges& out) {
  const auto key = [&](std::size_t i) { return std::make_tuple(served.at(places[i].scan_id), places[i].scan_id); };
  const auto unused = [&](std::size_t i) { return served.at(places[i].scan_id) < in_use_since; };
  std::unordered_set<std::int64_t> holding;
  for (const auto i : versions)
    if (!unused(i)) holding.insert(places[i].session_id);
  std::erase_if(versions, [&](std::size_t i) { return !unused(i); });
  std::sort(versions.begin(), versions.end(), [&](std::size_t a, std::size_t b) { return key(a) < key(b); });
  std::sort(visits.begin(), visits.end(), [&](std::size_t a, std::size_t b) { return key(a) > key(b); });
  std::size_t next = 0;
  for (const auto v : visits) {
    if (next == versions.size()) break;
    if (!holding.insert(places[v].session_id).second) continue;
    setKept(places[versions[next++]], false, out);
    setKept(places[v], true, out);
  }
}

// When the first scan of the ended sessions that have surplus scans (the visits since the last compaction) was
// stored; nullopt when there are none.
std::optional<double> visitsBegan(const std::vector<PlaceRecord>& places,
                                  const std::unordered_set<std::int64_t>& open_sessions) {
  std::unordered_set<std::int64_t> visiting;
  for (const auto& p : places)
    if (!p.kept && !open_sessions.count(p.session_id)) visiting.insert(p.session_id);
  std::optional<double> began;
  for (const auto& p : places)
    if (visiting.count(p.session_id)) began = std::min(began.value_or(p.added_at), p.added_at);
  return began;
}

}  // namespace

VersionChanges rebalanceVersions(std::vector<PlaceRecord>& places, const std::vector<storage::LoopRecord>& loops,
                                 const LifelongOptions& options,
                                 const std::unordered_set<std::int64_t>& open_sessions) {
  VersionChanges out;
  // The latest visits as the map stands, before steps 1 and 2 (whose changes then take no part in step 3).
  const auto began = visitsBegan(places, open_sessions);
  std::unordered_set<std::int64_t> settled;
  const auto settle = [&](PlaceRecord& p, bool kept) {
    setKept(p, kept, out);
    settled.insert(p.scan_id);
  };
  const auto max = static_cast<std::int64_t>(options.max_versions_per_place);
  std::unordered_map<std::int64_t, std::int64_t> count, seen;
  for (const auto& p : places) count[p.place_id] += p.kept ? 1 : 0;
  for (auto& p : places)  // 1. oldest first (scan-id order): the first `max` versions stay
    if (p.kept && ++seen[p.place_id] > max) {
      --count[p.place_id];
      settle(p, false);
    }
  for (auto it = places.rbegin(); it != places.rend(); ++it)  // 2. newest first
    if (!it->kept && count[it->place_id] < max) {
      ++count[it->place_id];
      settle(*it, true);
    }
  if (!began) return out;
  // 3. By place (ordered, for a deterministic order of changes): its versions and its latest visits.
  std::map<std::int64_t, std::pair<std::vector<std::size_t>, std::vector<std::size_t>>> by_place;
  for (std::size_t i = 0; i < places.size(); ++i)
    if (!open_sessions.count(places[i].session_id) && !settled.count(places[i].scan_id))
      (places[i].kept ? by_place[places[i].place_id].first : by_place[places[i].place_id].second).push_back(i);
  const auto served = lastServed(places, loops);
  for (auto& [place, scans] : by_place)
    if (!scans.first.empty() && !scans.second.empty())
      replaceUnused(places, std::move(scans.first), std::move(scans.second),
                    *began - options.session_retention_h * 3600.0, served, out);
  return out;
}

}  // namespace sglc::closing
