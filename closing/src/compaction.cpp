#include "sglc/closing/compaction.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

#include "sglc/closing/versions.hpp"

namespace sglc::closing {
namespace {

using storage::LoopRecord;
using storage::PlaceRecord;

PlaceTie tieOf(const LoopRecord& l) { return {l.candidate_scan, l.probability, l.T.block<3, 1>(0, 3).norm()}; }

// The sessions whose newest placed scan was stored less than the retention ago (none with the policy off).
std::unordered_set<std::int64_t> openSessions(const std::vector<PlaceRecord>& places, const LifelongOptions& options,
                                              double now_s) {
  std::unordered_map<std::int64_t, double> last;
  for (const auto& p : places) last[p.session_id] = std::max(last[p.session_id], p.added_at);
  std::unordered_set<std::int64_t> open;
  if (options.enabled())
    for (const auto& [session, at] : last)
      if (now_s - at < options.session_retention_h * 3600.0) open.insert(session);
  return open;
}

// Places for the map's scans that have none, in scan-id order, from their recorded loops to earlier scans. Scans
// of open sessions are left to their ingest: one being stored now gets its place from its own loops, which a
// compaction that read the map a moment before would not see (and would overwrite the ingest's place with).
std::int64_t placeUnplaced(storage::MapStore& store, const std::string& map, const LifelongOptions& options,
                           const std::vector<storage::GraphNodeRecord>& nodes, const std::vector<LoopRecord>& loops,
                           const std::vector<PlaceRecord>& before, const std::unordered_set<std::int64_t>& open) {
  std::unordered_map<std::int64_t, PlaceRecord> placed;
  std::unordered_map<std::int64_t, std::int64_t> versions;
  for (const auto& p : before) {
    placed[p.scan_id] = p;
    if (p.kept) ++versions[p.place_id];
  }
  std::unordered_map<std::int64_t, std::vector<PlaceTie>> ties;
  for (const auto& l : loops)
    if (l.candidate_scan < l.query_scan) ties[l.query_scan].push_back(tieOf(l));
  const PlaceLookup lookup{[&](std::int64_t id) -> std::optional<PlaceRecord> {
                             const auto it = placed.find(id);
                             return it == placed.end() ? std::nullopt : std::optional(it->second);
                           },
                           [&](std::int64_t place) { return versions[place]; }};
  std::vector<PlaceRecord> records;
  for (const auto& n : nodes) {
    if (placed.count(n.scan_id) || open.count(n.session_id)) continue;
    const auto it = ties.find(n.scan_id);
    for (const auto& r :
         placeScan(n.scan_id, it == ties.end() ? std::vector<PlaceTie>{} : it->second, options, lookup)) {
      placed[r.scan_id] = r;
      if (r.kept) ++versions[r.place_id];
      records.push_back(r);
    }
  }
  if (!records.empty()) store.setPlaces(map, records);
  return static_cast<std::int64_t>(records.size());
}

// The covariance a loop moved over `d` metres of odometry gains (translation then rotation, m and rad).
Mat6d odometryCovariance(const OdometryNoise& n, double d) {
  const double st = n.sigma_m + n.sigma_per_m * d, sr = (n.sigma_deg + n.sigma_deg_per_m * d) * M_PI / 180.0;
  Mat6d c = Mat6d::Zero();
  c.diagonal() << st * st, st * st, st * st, sr * sr, sr * sr, sr * sr;
  return c;
}

// The adjoint of T on a (translation, rotation) perturbation: T Exp(xi) T^-1 = Exp(Ad(T) xi).
Mat6d adjoint(const Mat4d& T) {
  const Eigen::Matrix3d R = T.block<3, 3>(0, 0);
  const Eigen::Vector3d t = T.block<3, 1>(0, 3);
  Eigen::Matrix3d tx;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  Mat6d ad = Mat6d::Zero();
  ad.block<3, 3>(0, 0) = R;
  ad.block<3, 3>(0, 3) = tx * R;
  ad.block<3, 3>(3, 3) = R;
  return ad;
}

// A loop's end moved from scan `from` to scan `to` of the same session: T gains the odometry between them.
struct Anchor {
  std::int64_t scan = 0;
  Mat4d to_from = Mat4d::Identity();  // points of `from` into the frame of `to`
  bool moved = false;
};

// A loop moved onto scans that stay, how far (m, both ends' moves together), and the scans it was moved onto.
struct MovedLoop {
  LoopRecord loop;
  double moved_m = 0;
  std::vector<std::int64_t> anchors;
};

class LoopMover {
 public:
  LoopMover(const std::vector<storage::GraphNodeRecord>& nodes, const std::unordered_set<std::int64_t>& retired,
            const OdometryNoise& noise)
      : retired_(retired), noise_(noise) {
    for (const auto& n : nodes) {
      by_id_[n.scan_id] = &n;
      if (!retired.count(n.scan_id) && n.odometry_pose) sessions_[n.session_id].emplace(n.seq, &n);
    }
  }

  // The loop with its retired ends moved to their sessions' nearest scans that stay; nullopt when an end has
  // none (no odometry, or its session keeps nothing) or both ends become one scan.
  std::optional<MovedLoop> move(const LoopRecord& l) const {
    const auto q = anchor(l.query_scan), c = anchor(l.candidate_scan);
    // Without an information matrix (refinement off, or recorded before schema 3) the pose graph weighs a loop by
    // its residual alone, which says nothing of the odometry it would be moved over: such loops are not moved.
    if (!q || !c || q->scan == c->scan || !l.information) return std::nullopt;
    MovedLoop m;
    LoopRecord& out = m.loop;
    out = l;
    out.id = 0;
    out.query_scan = q->scan;
    out.candidate_scan = c->scan;
    // T maps candidate points into the query's frame: p_q' = to_from(q) T inverse(to_from(c)) p_c'.
    out.T = q->to_from * l.T * c->to_from.inverse();
    m.moved_m = q->to_from.block<3, 1>(0, 3).norm() + c->to_from.block<3, 1>(0, 3).norm();
    out.information = movedInformation(*l.information, out.T, q->to_from, c->to_from);
    for (const auto& a : {*q, *c})
      if (a.moved) m.anchors.push_back(a.scan);
    return m;
  }

 private:
  std::optional<Anchor> anchor(std::int64_t scan) const {
    if (!retired_.count(scan)) return Anchor{scan};
    const auto n = by_id_.find(scan);
    if (n == by_id_.end() || !n->second->odometry_pose) return std::nullopt;
    const auto s = sessions_.find(n->second->session_id);
    if (s == sessions_.end() || s->second.empty()) return std::nullopt;
    // The nearest seq that stays; the earlier one on a tie.
    const auto& kept = s->second;
    const auto seq = n->second->seq;
    auto after = kept.lower_bound(seq);
    auto pick = after;
    if (after == kept.end() || (after != kept.begin() && seq - std::prev(after)->first <= after->first - seq))
      pick = std::prev(after);
    const auto* to = pick->second;
    return Anchor{to->scan_id, to->odometry_pose->inverse() * *n->second->odometry_pose, true};
  }

  // The information of the moved loop T' = Q T C^-1. The pose graph's error of a loop is a right perturbation of T
  // (in the candidate's frame, translation first), so moving the candidate end by C turns an error xi into
  // Ad(C) xi: the information becomes Ad(C)^-T I Ad(C)^-1. The odometry over each end's move adds its covariance:
  // the candidate end's in the new candidate frame, the query end's (a left perturbation) through Ad(T'^-1).
  // (I^-1 + S)^-1 is computed as I (1 + S I)^-1: no inverse of I, which may be singular in degenerate directions.
  Mat6d movedInformation(const Mat6d& info, const Mat4d& moved_T, const Mat4d& Q, const Mat4d& C) const {
    const Mat6d ad_c_inv = adjoint(C.inverse());
    const Mat6d info_c = ad_c_inv.transpose() * info * ad_c_inv;
    const Mat6d ad_t_inv = adjoint(moved_T.inverse());
    const Mat6d added = ad_t_inv * odometryCovariance(noise_, Q.block<3, 1>(0, 3).norm()) * ad_t_inv.transpose() +
                        odometryCovariance(noise_, C.block<3, 1>(0, 3).norm());
    const Mat6d moved = info_c * (Mat6d::Identity() + added * info_c).inverse();
    return 0.5 * (moved + moved.transpose());
  }

  const std::unordered_set<std::int64_t>& retired_;
  const OdometryNoise noise_;
  std::unordered_map<std::int64_t, const storage::GraphNodeRecord*> by_id_;
  std::unordered_map<std::int64_t, std::map<std::int64_t, const storage::GraphNodeRecord*>> sessions_;
};

// The loops to keep of those moved: onto each scan that stays, while it has fewer than `per_anchor` loops in all
// (`degree`: the loops it keeps; so the bound holds over every compaction, not each), those moved the least
// (their poses carry the least odometry; ties: the surer, then the lower ids). Without a bound, every ended
// session whose few kept scans took all its retired scans' loops would add dozens of long, weak loops to the
// graph, which would grow with the days driven, not with the map. In the order the store should keep them: of
// two loops moved onto one pair, it keeps the first.
std::vector<LoopRecord> fewestPerAnchor(std::vector<MovedLoop> moved, int per_anchor,
                                        std::unordered_map<std::int64_t, int> degree) {
  std::sort(moved.begin(), moved.end(), [](const MovedLoop& a, const MovedLoop& b) {
    return std::make_tuple(a.moved_m, -a.loop.probability.value_or(0), a.loop.query_scan, a.loop.candidate_scan) <
           std::make_tuple(b.moved_m, -b.loop.probability.value_or(0), b.loop.query_scan, b.loop.candidate_scan);
  });
  std::vector<LoopRecord> out;
  for (auto& m : moved) {
    bool room = true;
    for (const auto a : m.anchors) room = room && degree[a] < per_anchor;
    if (!room) continue;
    for (const auto a : m.anchors) ++degree[a];
    out.push_back(std::move(m.loop));
  }
  return out;
}

}  // namespace

CompactionReport compact(storage::MapStore& store, const std::string& map, const LifelongOptions& options,
                         const OdometryNoise& noise, double now_s) {
  CompactionReport report;
  const auto nodes = store.graphNodes(map);
  const auto loops = store.loops(map);
  auto places = store.places(map);
  report.placed = placeUnplaced(store, map, options, nodes, loops, places, openSessions(places, options, now_s));
  if (report.placed > 0) places = store.places(map);
  const auto open = openSessions(places, options, now_s);
  if (options.enabled()) {
    const auto changes = rebalanceVersions(places, loops, options, open);
    if (!changes.changed.empty()) store.setPlaces(map, changes.changed);
    report.promoted = changes.promoted;
    report.demoted = changes.demoted;
  }
  std::unordered_set<std::int64_t> places_seen;
  for (const auto& p : places) {
    places_seen.insert(p.place_id);
    report.versions += p.kept ? 1 : 0;
  }
  report.places = static_cast<std::int64_t>(places_seen.size());
  if (!options.enabled()) return report;
  report.open_sessions = static_cast<std::int64_t>(open.size());
  std::unordered_set<std::int64_t> retired;
  std::vector<std::int64_t> ids;
  for (const auto& p : places)
    if (!p.kept && !open.count(p.session_id)) {
      retired.insert(p.scan_id);
      ids.push_back(p.scan_id);
    }
  if (ids.empty()) return report;
  const LoopMover mover(nodes, retired, noise);
  std::vector<MovedLoop> candidates;
  std::unordered_map<std::int64_t, int> degree;  // of the scans that stay: the loops they keep
  for (const auto& l : loops) {
    if (!retired.count(l.query_scan) && !retired.count(l.candidate_scan)) {
      ++degree[l.query_scan];
      ++degree[l.candidate_scan];
      continue;
    }
    if (auto m = mover.move(l))
      candidates.push_back(std::move(*m));
    else
      ++report.loops_dropped;
  }
  const auto movable = static_cast<std::int64_t>(candidates.size());
  const auto moved = fewestPerAnchor(std::move(candidates), options.max_moved_loops_per_scan, std::move(degree));
  report.loops_dropped += movable - static_cast<std::int64_t>(moved.size());
  const auto done = store.retireScans(map, ids, moved);
  report.retired = done.scans;
  report.retired_bytes = done.bytes;
  report.loops_moved = done.loops_kept;
  report.loops_dropped += static_cast<std::int64_t>(moved.size()) - done.loops_kept;
  return report;
}

}  // namespace sglc::closing
