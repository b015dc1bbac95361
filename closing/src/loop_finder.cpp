#include "sglc/closing/loop_finder.hpp"

#include "sglc/elapsed.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <unordered_set>

namespace sglc::closing {
namespace {

using storage::StorageError;

// A loop probability to a thousandth (0-999): the resolution at which candidates are ranked by it.
int probabilityRank(double p) {
  if (!(p > 0.0)) return 0;  // NaN too
  return std::min(999, static_cast<int>(std::floor(std::min(p, 1.0) * 1000.0)));
}

constexpr std::uint32_t kMaxTopK = 100;
constexpr std::uint32_t kMaxCandidates = 200;

// The options' checks, in the order a caller with several mistakes learns of them.
Ranking checkedRanking(const QueryOptions& opt, std::uint32_t* candidates) {
  Ranking r;
  r.top_k = opt.top_k ? opt.top_k : 5u;
  if (r.top_k > kMaxTopK) throw InputError("top_k must be at most 100");
  *candidates = opt.candidates ? opt.candidates : std::max<std::uint32_t>(static_cast<std::uint32_t>(r.top_k), 10u);
  if (*candidates > kMaxCandidates) throw InputError("candidates must be at most 200");
  if (opt.exclude_recent < 0 || !std::isfinite(opt.exclude_seconds) || opt.exclude_seconds < 0)
    throw InputError("exclude_recent and exclude_seconds must be >= 0");
  r.refine = opt.refine;
  r.known_loops = opt.known_loops;
  if (r.known_loops && !r.refine) throw InputError("known_loops asks for poses: it cannot go with refine = false");
  r.include_rejected = opt.include_rejected || opt.known_loops;
  if (opt.min_score && !std::isfinite(*opt.min_score)) throw InputError("min_score is not finite");
  r.min_score = opt.min_score;
  return r;
}

// Where the search may look: the scope as filters of the search request.
void applyScope(const QueryOptions& opt, const QueryOrigin& who, storage::SearchRequest* req) {
  switch (opt.scope) {
    case Scope::kWholeMap:
      break;
    case Scope::kSameRobot:
    case Scope::kOtherRobots:
      if (who.robot.empty()) throw InputError("scope SAME_ROBOT / OTHER_ROBOTS needs the query's robot");
      (opt.scope == Scope::kSameRobot ? req->robots : req->exclude_robots).push_back(who.robot);
      break;
    case Scope::kSessions:
      if (opt.sessions.empty() && opt.session_refs.empty())
        throw InputError("scope SESSIONS needs at least one 'robot/session' in sessions or one session_refs entry");
      for (const auto& s : opt.sessions) {
        const auto slash = s.find('/');
        if (slash == std::string::npos) throw InputError("sessions entry '" + s + "' is not 'robot/session'");
        req->session_refs.emplace_back(s.substr(0, slash), s.substr(slash + 1));
      }
      for (const auto& r : opt.session_refs) req->session_refs.emplace_back(r.robot, r.session);
      break;
    case Scope::kUnknown:
      throw InputError("unknown scope");
  }
}

}  // namespace

void Execution::forEach(std::size_t n, const std::function<void(std::size_t)>& fn) const {
  if (parallel_for) {
    parallel_for(n, fn);
    return;
  }
  for (std::size_t i = 0; i < n; ++i) fn(i);
}

float descriptorDistance(const std::vector<float>& a, const std::vector<float>& b) {
  double d2 = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d2 += std::pow(double(a[i]) - double(b[i]), 2);
  return static_cast<float>(std::sqrt(d2));
}

std::pair<std::shared_ptr<const Fingerprint>, QueryOrigin> LoopFinder::storedQuery(const std::string& map,
                                                                                   std::int64_t scan_id) const {
  const auto info = store_.scanInfo(scan_id);
  if (!info || info->map != map)
    throw StorageError(StorageError::Code::kNotFound, "map '" + map + "' has no scan " + std::to_string(scan_id));
  auto fp = store_.fingerprint(scan_id);
  if (!fp) throw StorageError(StorageError::Code::kNotFound, "scan " + std::to_string(scan_id) + " was deleted");
  // A copy for the query: what a query derives and keeps with its fingerprint (the plane lookup) then dies with
  // the query instead of growing the cached one past what the cache counted when it took it.
  fp = std::make_shared<const Fingerprint>(*fp);
  return {std::move(fp), QueryOrigin{map, info->robot, info->session, info->seq, info->stamp, scan_id}};
}

std::vector<storage::SearchHit> LoopFinder::listed(const Fingerprint& query, const std::string& map,
                                                   const std::vector<std::int64_t>& ids, std::size_t max) const {
  if (ids.size() > max) throw InputError("verify_scan_ids: at most " + std::to_string(max));
  std::vector<storage::SearchHit> hits;
  std::unordered_set<std::int64_t> seen;
  for (const auto id : ids) {
    if (!seen.insert(id).second) throw InputError("verify_scan_ids repeats scan " + std::to_string(id));
    const auto info = store_.scanInfo(id);
    const auto fp = info && info->map == map ? store_.fingerprint(id) : nullptr;
    if (!fp) throw StorageError(StorageError::Code::kNotFound, "map '" + map + "' has no scan " + std::to_string(id));
    if (fp->descriptor.size() != query.descriptor.size())
      throw InputError("scan " + std::to_string(id) + " has another descriptor layout");
    hits.push_back({id, descriptorDistance(query.descriptor, fp->descriptor)});
  }
  return hits;
}

std::vector<storage::SearchHit> LoopFinder::candidates(const Fingerprint& query, const QueryOrigin& who,
                                                       const QueryOptions& opt, std::uint32_t k, const Execution& exec,
                                                       const ViewRanking& view) const {
  storage::SearchRequest req;
  req.map = who.map;
  req.descriptor = query.descriptor;
  req.k = static_cast<int>(k);
  req.self_robot = who.robot;
  req.self_session = who.session;
  req.self_seq = who.seq;
  req.exclude_recent = opt.exclude_recent;
  req.self_stamp = who.stamp;
  req.exclude_seconds = opt.exclude_seconds;
  if (who.self_scan) req.exclude_scan_ids.push_back(who.self_scan);
  applyScope(opt, who, &req);  // checked even when the candidates are listed
  if (!opt.verify_scan_ids.empty()) return listed(query, who.map, opt.verify_scan_ids);
  return viewRanked(view, std::move(req), exec);
}

std::vector<storage::SearchHit> LoopFinder::viewRanked(const ViewRanking& ranking, storage::SearchRequest req,
                                                       const Execution& exec) const {
  // Full views, and narrow ones without structure in view: the descriptor's order (spare the reads).
  if (!ranking.active()) return store_.search(req);
  const auto k = static_cast<std::size_t>(req.k);
  req.k = std::max(req.k, pipeline_.config().view_search.max_scans);
  auto hits = store_.search(req);
  std::vector<double> similarity(hits.size(), -1.0);  // -1: deleted meanwhile
  // Each stored scan's context from the store's own cache of them: a map larger than the fingerprint cache
  // is not read back scan by scan on every narrow query.
  const ViewMatcher& matcher = *ranking.queryView().matcher;
  exec.forEach(hits.size(), [&](std::size_t i) {
    if (i % 64 == 0) exec.checkAlive();
    const auto context = store_.viewContext(hits[i].scan_id, pipeline_.config().view_search);
    if (!context) return;
    similarity[i] = matcher.match(*context).similarity;
  });
  std::vector<std::size_t> order(hits.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::erase_if(order, [&](std::size_t i) { return similarity[i] < 0; });
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    if (similarity[a] != similarity[b]) return similarity[a] > similarity[b];
    if (hits[a].distance != hits[b].distance) return hits[a].distance < hits[b].distance;
    return hits[a].scan_id < hits[b].scan_id;
  });
  std::vector<storage::SearchHit> out;
  for (std::size_t i = 0; i < order.size() && out.size() < k; ++i) out.push_back(hits[order[i]]);
  return out;
}

std::vector<FoundLoop> LoopFinder::find(const Fingerprint& query, const QueryOrigin& origin,
                                        const QueryOptions& options, const Execution& exec, QueryTiming* timing) const {
  std::uint32_t n_candidates = 0;
  const auto ranking = checkedRanking(options, &n_candidates);
  // A NaN stamp would quietly turn exclude_seconds off.
  if (origin.stamp && !std::isfinite(*origin.stamp)) throw InputError("stamp is not finite");
  const auto t0 = Clock::now();
  const auto view = pipeline_.viewRanking(query);  // the query's view, computed once
  const auto hits = candidates(query, origin, options, n_candidates, exec, view);
  timing->search_ms = msSince(t0);
  auto found = verify(query, hits, ranking, exec, timing, &view);
  for (auto& f : found)
    if (const auto info = store_.scanInfo(f.scan_id)) {
      f.robot = info->robot;
      f.session = info->session;
      f.seq = info->seq;
    }
  return found;
}

std::vector<FoundLoop> LoopFinder::verify(const Fingerprint& query, const std::vector<storage::SearchHit>& hits,
                                          const Ranking& ranking, const Execution& exec, QueryTiming* timing,
                                          const ViewRanking* view) const {
  struct Verified {
    FoundLoop loop;
    std::shared_ptr<const Fingerprint> fp;
  };
  auto t0 = Clock::now();
  // Candidates are verified independently (at once where exec allows) and kept in search order. Loops from the
  // background alone cost more to find: only the first candidates of the search may give one; more of a narrow
  // view's, which its view context ranks and whose search is narrower.
  const auto background = pipeline_.backgroundCandidates(query);
  // The query's plane lookup, built here once rather than by every worker that first misses it at once.
  if (pipeline_.config().refine.enabled && !hits.empty()) planeIndexOf(query, pipeline_.config().refine.max_corr_m);
  std::vector<std::optional<Verified>> verified(hits.size());
  std::vector<const char*> outcome(hits.size(), nullptr);  // "" verified, else the reason; null: not checked
  exec.forEach(hits.size(), [&](std::size_t i) {
    exec.checkAlive();
    auto fp = store_.fingerprint(hits[i].scan_id);
    if (!fp) return;  // deleted meanwhile
    auto r = pipeline_.verify(query, *fp, i < background, view);
    outcome[i] = r.is_loop ? "" : r.reason;
    if (!r.is_loop && !(ranking.include_rejected || ranking.known_loops)) return;
    Verified v;
    v.loop.scan_id = hits[i].scan_id;
    v.loop.descriptor_distance = hits[i].distance;
    v.loop.result = std::move(r);
    v.fp = std::move(fp);
    verified[i] = std::move(v);
  });
  std::vector<Verified> results;
  for (auto& v : verified)
    if (v) results.push_back(std::move(*v));
  timing->verify_ms = msSince(t0);
  for (const char* o : outcome)
    if (o && *o)
      timing->refused.push_back(o);
    else if (o)
      ++timing->verified;
  // Loops first, by probability to a thousandth; the model cannot tell 0.9995 from 0.9999 apart in any
  // meaningful way, so among candidates it is that sure of the nearer pose ranks first (the revisit that shares
  // most with the query, its loop the shortest lever); then the scan id.
  std::stable_sort(results.begin(), results.end(), [](const Verified& a, const Verified& b) {
    const auto& ra = a.loop.result;
    const auto& rb = b.loop.result;
    if (ra.is_loop != rb.is_loop) return ra.is_loop;
    const int ka = probabilityRank(ra.score), kb = probabilityRank(rb.score);
    if (ka != kb) return ka > kb;
    const double ta = ra.T.topRightCorner<3, 1>().norm(), tb = rb.T.topRightCorner<3, 1>().norm();
    if (ta != tb) return ta < tb;
    return a.loop.scan_id < b.loop.scan_id;
  });
  if (ranking.min_score)
    std::erase_if(results,
                  [&](const Verified& v) { return v.loop.result.is_loop && v.loop.result.score < *ranking.min_score; });
  if (results.size() > ranking.top_k) results.resize(ranking.top_k);
  t0 = Clock::now();
  if (ranking.refine)
    exec.forEach(results.size(), [&](std::size_t i) {
      exec.checkAlive();
      pipeline_.refine(query, *results[i].fp, results[i].loop.result, ranking.known_loops);
    });
  timing->refine_ms = msSince(t0);
  std::vector<FoundLoop> out;
  out.reserve(results.size());
  for (auto& v : results) out.push_back(std::move(v.loop));
  return out;
}

}  // namespace sglc::closing
