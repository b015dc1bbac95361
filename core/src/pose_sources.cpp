#include "pose_sources.hpp"

#include <cmath>
#include <numbers>

#include "sglc/bev_search.hpp"
#include "sglc/consensus.hpp"
#include "sglc/registration.hpp"

namespace sglc::detail {
namespace {

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

// The heading (T_q_c's yaw, radians) the narrow view's context gives, and a sector either side.
std::vector<double> viewHeadings(const PairView& view) {
  if (view.context.similarity <= 0) return {};
  constexpr double kTurn = 2.0 * std::numbers::pi, kSector = kTurn / ViewContext::kSectors;
  const double h = view.query_saw_less ? view.context.heading : kTurn - view.context.heading;
  std::vector<double> headings;
  for (const double d : {-kSector, 0.0, kSector}) headings.push_back(std::fmod(h + d + 2.0 * kTurn, kTurn));
  return headings;
}

}  // namespace

LandmarkPose landmarkPose(const Fingerprint& query, const Fingerprint& candidate, const Config& c) {
  LandmarkPose out;
  auto matches = matchNodes(query.nodes, query.node_descriptors, candidate.nodes, candidate.node_descriptors, c.match);
  if (auto pruned = pruneMatches(query.nodes, candidate.nodes, matches, c.match);
      static_cast<int>(pruned.size()) >= c.match.prune_min_kept)
    matches = std::move(pruned);
  auto ransac = coarsePose(query, candidate, matches, c.ransac);
  out.source = PoseSource::kLandmarks;
  // Small graphs: descriptors too unstable to pair nodes; when they give no pose, geometry pairs them.
  if (!ransac.found && consensusApplies(c.match, query.nodes.size(), candidate.nodes.size())) {
    auto agreed = consensusMatches(query.nodes, query.node_descriptors, candidate.nodes, candidate.node_descriptors,
                                   c.match, c.ransac);
    auto second = coarsePose(query, candidate, agreed, c.ransac);
    if (second.found) {
      matches = std::move(agreed);
      ransac = std::move(second);
      out.source = PoseSource::kConsensus;
    }
  }
  out.matches = static_cast<int>(matches.size());
  if (!ransac.found) {
    out.source = PoseSource::kNone;
    out.failure = out.matches < 3 ? "fewer than 3 node matches" : "no pose agrees with enough node matches";
    return out;
  }
  out.T = ransac.T;
  out.inliers = static_cast<int>(ransac.inliers.size());
  out.graph_similarity = std::exp(-ransac.mean_residual);
  for (int k : ransac.inliers) out.inlier_pairs.push_back(matches[k]);
  return out;
}

std::vector<Mat4d> overlayPoses(const Fingerprint& query, const Fingerprint& candidate, const PairView& view,
                                const Config& c) {
  const auto headings = view.narrow ? viewHeadings(view) : wallHeadings(query.planes, candidate.planes, 2);
  if (headings.empty()) return {};
  BevSearchConfig search = c.bev_search;
  // The context's three headings span 8.4 deg, about 5 steps of the default 2 deg: at most 8 steps' shifts.
  if (view.narrow) search.keep = 8 * c.view_search.shifts_per_heading;
  std::vector<Mat4d> poses;
  for (const auto& h : searchBevPose(query.background, candidate.background, query.background_cell, search, headings,
                                     false, view.narrow ? c.view_search.shifts_per_heading : 1))
    poses.push_back(h.T);
  return poses;
}

}  // namespace sglc::detail
