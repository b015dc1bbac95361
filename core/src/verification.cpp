// Pipeline::verify: the coarse pose from node matches, its alignment on the background planes, and the loop
// decision (docs/METHOD.md, sections 7 and 8).
#include <algorithm>
#include <cmath>

#include "agreement.hpp"
#include "narrow_view.hpp"
#include "pose_guard.hpp"
#include "sglc/bev_search.hpp"
#include "sglc/consensus.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/view_context.hpp"

namespace sglc {
namespace {

bool sameGeometry(const Fingerprint& a, const Fingerprint& b) {
  return a.layout.num_classes == b.layout.num_classes && a.layout.bins == b.layout.bins &&
         a.layout.k_eigen == b.layout.k_eigen && a.layout.rings == b.layout.rings &&
         a.layout.orders == b.layout.orders && a.d_max == b.d_max && a.d_i == b.d_i &&
         a.background_cell == b.background_cell && a.plane_voxel == b.plane_voxel;
}

// RANSAC over the matched node centres (not found with fewer than 3 matches).
RansacResult coarsePose(const Fingerprint& query, const Fingerprint& candidate, const std::vector<Match>& matches,
                        const RansacConfig& config) {
  if (matches.size() < 3) return {};
  std::vector<Vec3d> q, t;
  for (const auto& [i, j] : matches) {
    q.push_back(query.nodes[i].center.cast<double>());
    t.push_back(candidate.nodes[j].center.cast<double>());
  }
  return ransacRigid(q, t, config);
}

// Small graphs: descriptors too unstable to pair nodes; when the descriptor matches give no pose, geometry pairs
// them (consensusMatches) and replaces `matches` and `ransac`. Pairs found by geometry alone carry less evidence,
// so the graph similarity threshold returned is then the stricter consensus_t_g.
double withConsensus(const Fingerprint& query, const Fingerprint& candidate, const Config& c,
                     std::vector<Match>& matches, RansacResult& ransac) {
  if (ransac.found || !consensusApplies(c.match, query.nodes.size(), candidate.nodes.size())) return c.verify.t_g;
  auto agreed = consensusMatches(query.nodes, query.node_descriptors, candidate.nodes, candidate.node_descriptors,
                                 c.match, c.ransac);
  auto second = coarsePose(query, candidate, agreed, c.ransac);
  if (!second.found) return c.verify.t_g;
  matches = std::move(agreed);
  ransac = std::move(second);
  return std::max(c.verify.t_g, c.match.consensus_t_g);
}

// Node inliers of the coarse pose that lie within `gate` of each other under T.
int inliersWithin(const Fingerprint& query, const Fingerprint& candidate, const std::vector<Match>& matches,
                  const std::vector<int>& inliers, const Mat4d& T, double gate) {
  const Mat3d R = T.topLeftCorner<3, 3>();
  const Vec3d t = T.topRightCorner<3, 1>();
  int n = 0;
  for (int k : inliers) {
    const auto& [i, j] = matches[k];
    n += (R * candidate.nodes[j].center.cast<double>() + t - query.nodes[i].center.cast<double>()).norm() <= gate;
  }
  return n;
}

// Of the plane features in the height band both scans see (centroid at most max_z above the sensor), the share
// the scan with fewer has explained by the other under T: min(candidate planes with a query plane, distinct query
// planes they reach) / min(band planes of each). A sparse sensor's planes are matched against a dense one's
// without its missing planes counting against it.
double bandOverlap(const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T, double max_z,
                   const RefineConfig& config) {
  std::size_t in_query = 0, in_candidate = 0, explained = 0;
  for (const auto& p : query.planes) in_query += p.centroid.z() <= max_z;
  std::vector<bool> reached(query.planes.size(), false);
  const Eigen::Matrix3f R = T.topLeftCorner<3, 3>().cast<float>();
  const Vec3f t = T.topRightCorner<3, 1>().cast<float>();
  for (const auto& p : candidate.planes) {
    if (p.centroid.z() > max_z) continue;
    ++in_candidate;
    const int q = query.plane_index.nearest(query.planes, R * p.centroid + t, R * p.normal, config.max_corr_m,
                                            config.min_normal_cosine);
    if (q < 0) continue;
    ++explained;
    reached[static_cast<std::size_t>(q)] = true;
  }
  const auto distinct = static_cast<std::size_t>(std::count(reached.begin(), reached.end(), true));
  const std::size_t fewer = std::min(in_query, in_candidate);
  return fewer ? static_cast<double>(std::min(explained, distinct)) / static_cast<double>(fewer) : 0.0;
}

}  // namespace

LoopResult Pipeline::verify(const Fingerprint& query, const Fingerprint& candidate, bool background) const {
  if (!sameGeometry(query, candidate))
    throw InputError("fingerprints were built with different descriptor or voxel parameters");
  const auto& c = config_;
  LoopResult r;
  auto matches = matchNodes(query.nodes, query.node_descriptors, candidate.nodes, candidate.node_descriptors, c.match);
  if (auto pruned = pruneMatches(query.nodes, candidate.nodes, matches, c.match);
      static_cast<int>(pruned.size()) >= c.match.prune_min_kept)
    matches = std::move(pruned);
  auto ransac = coarsePose(query, candidate, matches, c.ransac);
  const double t_g = withConsensus(query, candidate, c, matches, ransac);
  r.matches = static_cast<int>(matches.size());
  const auto& v = c.verify;
  const bool few_nodes =
      v.background_max_nodes > 0 &&
      static_cast<int>(std::min(query.nodes.size(), candidate.nodes.size())) <= v.background_max_nodes;
  if (!ransac.found) {
    r.reason = r.matches < 3 ? "fewer than 3 node matches" : "no pose agrees with enough node matches";
    return background && few_nodes ? backgroundLoop(query, candidate, std::move(r), false) : r;
  }
  r.T = ransac.T;
  r.inliers = static_cast<int>(ransac.inliers.size());
  r.graph_similarity = std::exp(-ransac.mean_residual);
  auto agreement = [&](const Mat4d& T) { return detail::agreementAt(query, candidate, T, v); };
  r.background_similarity = agreement(r.T);
  // The coarse pose aligned on the background planes (section 8): the background and the plane confirmation
  // are judged there.
  RefineResult planes;
  bool aligned = false;
  const bool align_on = v.align_max_shift_m > 0 && c.refine.enabled;
  if (r.graph_similarity >= t_g && align_on && r.background_similarity >= v.align_min_background) {
    planes = refinePlanes(query.planes, query.plane_index, candidate.planes, {}, r.T, c.refine);
    aligned = planes.iterations > 0 && planes.rmse <= v.confirm_max_rmse_m &&
              detail::movedWithin(r.T, planes.T, v.align_max_shift_m, v.align_max_turn_deg) &&
              inliersWithin(query, candidate, matches, ransac.inliers, planes.T, v.align_node_gate_m) >= 3;
    if (aligned) r.background_similarity = agreement(planes.T);
  }
  const double translation = (aligned ? planes.T : r.T).topRightCorner<3, 1>().norm();
  r.score = r.graph_similarity * r.background_similarity * (1.0 - std::exp(-r.inliers / 3.0));
  // Nearer revisits rank first: they share more of the scene, so their pose is the more reliable.
  if (v.score_distance_m > 0) r.score *= std::exp(-translation / v.score_distance_m);
  if (r.graph_similarity < t_g)
    r.reason = t_g > v.t_g ? "graph similarity below match.consensus_t_g (nodes paired by consensus)"
                           : "graph similarity below t_g";
  else if (r.background_similarity < v.t_b)
    r.reason = "background similarity below t_b";
  else if (v.max_translation > 0 && translation > v.max_translation)
    r.reason = "translation exceeds verify.max_translation";
  else
    r.is_loop = true;
  // Few node inliers are weak evidence (three or four landmarks align by chance between look-alike streets):
  // such a loop stands only if the background planes, aligned from the coarse pose, agree with it.
  bool refuted = false;  // the planes, aligned from the landmarks' pose, did not confirm it
  if (r.is_loop && r.inliers < v.confirm_below_inliers) {
    if (!align_on) planes = refinePlanes(query.planes, query.plane_index, candidate.planes, {}, r.T, c.refine);
    const bool near =
        align_on ? aligned : detail::movedWithin(r.T, planes.T, c.refine.max_shift_m, c.refine.max_turn_deg);
    if (!near || planes.iterations == 0 ||
        bandOverlap(query, candidate, planes.T, c.fingerprint.background_max_z_m, c.refine) < v.confirm_min_fitness ||
        planes.rmse > v.confirm_max_rmse_m || planes.horizontal_constraint < v.confirm_min_constraint) {
      r.is_loop = false;
      refuted = true;
      r.reason = "few node inliers and the background planes do not confirm the pose";
    }
  }
  if (r.is_loop && aligned) r.T = planes.T;
  // The inlier node pairs, for the fine stage.
  r.inlier_pairs.reserve(ransac.inliers.size());
  for (int k : ransac.inliers) r.inlier_pairs.push_back(matches[k]);
  return !r.is_loop && background && few_nodes ? backgroundLoop(query, candidate, std::move(r), refuted) : r;
}

namespace {

// The pose a background-only loop is judged at: the plane fit from the best overlay.
struct Fitted {
  RefineResult planes;    // planes.T is the pose
  double overlap = -1.0;  // band-plane overlap there; negative when no overlay got a fit
};

// The plane fit from each overlay at `headings`; the one whose planes explain most stands. A narrow pair's
// overlays (`narrow` not null) all get the fit, several shifts at each heading, and the one whose planes and view
// agree most stands: its walls along a street overlay alike all along it, and its near agreement is too weak a
// clue to drop any before the fit.
Fitted fitOverlays(const Fingerprint& query, const Fingerprint& candidate, const Config& c,
                   const std::vector<double>& headings, const detail::NarrowPair* narrow) {
  BevSearchConfig search = c.bev_search;
  // The context's three headings span 8.4 deg, about 5 steps of the default 2 deg: at most 8 steps' shifts.
  if (narrow) search.keep = 8 * c.view_search.shifts_per_heading;
  Fitted best;
  double best_key = -1.0;
  for (const auto& h : searchBevPose(query.background, candidate.background, query.background_cell, search, headings,
                                     false, narrow ? c.view_search.shifts_per_heading : 1)) {
    // Most overlays of another place disagree already: spare them the plane fit.
    if (!narrow && detail::agreementAt(query, candidate, h.T, c.verify) < c.verify.background_min_overlay) continue;
    auto planes = refinePlanes(query.planes, query.plane_index, candidate.planes, {}, h.T, c.refine);
    if (planes.iterations == 0 || planes.correspondences < c.bev_search.min_correspondences) continue;
    const double overlap = bandOverlap(query, candidate, planes.T, c.fingerprint.background_max_z_m, c.refine);
    // A narrow pair's fits that cannot pass its plane bars do not compete (the key would prefer them).
    if (narrow && (overlap < c.view_search.min_overlap || planes.rmse > c.view_search.max_rmse_m)) continue;
    const double key =
        narrow ? overlap * detail::viewAgreement(*narrow, query, candidate, planes.T, c.view_search) : overlap;
    if (key <= best_key) continue;
    best_key = key;
    best.overlap = overlap;
    best.planes = std::move(planes);
  }
  return best;
}

// Whether `agreement` exceeds `level` anywhere the pose moves 2 or 4 m either way along the planes' free
// direction (a left motion: turned about the query's origin, then shifted). False when there is none.
template <class Agreement>
bool higherAlongStreet(const RefineResult& planes, const Agreement& agreement, double level) {
  if (planes.weak_shift.isZero()) return false;
  for (const double s : {-4.0, -2.0, 2.0, 4.0}) {
    Mat4d T = Mat4d::Identity();
    T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(s * planes.weak_turn, Vec3d::UnitZ()).toRotationMatrix();
    T.topRightCorner<2, 1>() = s * planes.weak_shift;
    if (agreement(Mat4d(T * planes.T)) > level) return true;
  }
  return false;
}

}  // namespace

LoopResult Pipeline::backgroundLoop(const Fingerprint& query, const Fingerprint& candidate, LoopResult nodes,
                                    bool refuted) const {
  const auto& c = config_;
  const auto& v = c.verify;
  const auto& vs = c.view_search;
  if (!c.bev_search.enabled || !c.refine.enabled) return nodes;
  // A narrow view's walls overlay on too many streets at some heading: its overlay is searched only near the
  // heading its view context gives, and judged on its own field (section 8), or not at all without view_search.
  const double query_span = viewSpanDeg(query.background, query.background_cell);
  const double candidate_span = viewSpanDeg(candidate.background, candidate.background_cell);
  const bool narrow = std::min(query_span, candidate_span) < v.background_min_view_deg;  // isNarrowView
  const bool query_narrow = query_span <= candidate_span;  // of two narrow scans, the one that saw less
  if (narrow && !vs.enabled) {
    nodes.reason =
        "no loop from the landmarks, and a scan that saw less than verify.background_min_view_deg of the horizon "
        "gets none from its background alone without view_search";
    return nodes;
  }
  // Planes that already refused the landmarks' pose are not overruled on a lower bar: then the background must
  // also pass the plane confirmation's own limits.
  const double min_overlap =
      std::max(narrow ? vs.min_overlap : v.background_min_overlap, refuted ? v.confirm_min_fitness : 0.0);
  const double min_constraint =
      refuted ? std::max(v.background_min_constraint, v.confirm_min_constraint) : v.background_min_constraint;
  detail::NarrowPair pair;
  if (narrow) pair = detail::compareNarrow(query, candidate, query_narrow, vs);
  const auto headings = narrow ? detail::viewHeadings(pair) : wallHeadings(query.planes, candidate.planes, 2);
  if (headings.empty()) return nodes;
  const Fitted fit = fitOverlays(query, candidate, c, headings, narrow ? &pair : nullptr);
  const RefineResult& planes = fit.planes;
  const double translation = planes.T.topRightCorner<3, 1>().norm();
  if (fit.overlap < min_overlap || (v.max_translation > 0 && translation > v.max_translation))
    return nodes;  // the landmarks' verdict stands (also when no overlay got a fit)
  auto near = [&](const Mat4d& T) { return detail::agreementAt(query, candidate, T, v); };
  const double near_here = near(planes.T);
  // Pinned along the street by the planes, or by the near bird's-eye view (section 8's corridor rule).
  auto pinned = [&] {
    if (planes.horizontal_constraint >= min_constraint) return true;
    return v.background_pin_margin > 0 && planes.next_constraint >= min_constraint && !planes.weak_shift.isZero() &&
           !higherAlongStreet(planes, near, near_here - v.background_pin_margin);
  };
  LoopResult best;
  best.T = planes.T;
  if (narrow) {
    auto view = [&](const Mat4d& T) { return detail::viewAgreement(pair, query, candidate, T, vs); };
    const double agreement = view(planes.T);
    const double evidence = agreement * fit.overlap * pair.match.similarity;
    // Pinned by the planes, the near view or landmarks, and in any case not better along the street in its own.
    const bool view_pinned =
        (pinned() || detail::landmarksAt(query, candidate, planes.T, vs.landmark_gate_m) >= vs.pin_landmarks) &&
        !higherAlongStreet(planes, view, agreement);
    if (planes.rmse > vs.max_rmse_m || evidence < vs.min_evidence || !view_pinned) return nodes;
    best.background_similarity = agreement;
    best.score = evidence;
  } else {
    if (planes.rmse > v.background_max_rmse_m || near_here < v.background_min_agreement || !pinned()) return nodes;
    best.background_similarity = near_here;
    best.score = near_here * fit.overlap;
  }
  best.is_loop = true;
  best.matches = nodes.matches;
  if (v.score_distance_m > 0) best.score *= std::exp(-translation / v.score_distance_m);
  // The pose is the planes' own: refined already (the fine stage has no matched instances to work on).
  best.refined = true;
  best.fitness = planes.fitness;
  best.rmse = planes.rmse;
  best.information = planes.information;
  return best;
}

}  // namespace sglc
