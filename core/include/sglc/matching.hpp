// Node correspondences: Hungarian assignment on descriptor costs, then pruning by local triangles.
#pragma once

#include <utility>
#include <vector>

#include "sglc/config.hpp"
#include "sglc/graph.hpp"

namespace sglc {

using Match = std::pair<int, int>;  // (query node, candidate node)

// Minimum-cost assignment for a rectangular cost matrix (rows x cols). Returns, for each row, its column
// or -1 when the row is left unassigned (rows > cols). Deterministic; O(n^2 m).
std::vector<int> hungarian(const Eigen::MatrixXd& cost);

// Cost 1 - cos(f_q, f_c) for nodes of equal class whose box dimensions all differ by <= d_b and whose
// cosine >= min_cosine; the others are forbidden. Returns allowed assignments sorted by query node.
std::vector<Match> matchNodes(const std::vector<Node>& query, const Eigen::MatrixXf& query_desc,
                              const std::vector<Node>& candidate, const Eigen::MatrixXf& candidate_desc,
                              const MatchConfig& config);

// Keeps a match when at least t_m triangles (the node and two neighbours within d_l) have all three sorted
// sides equal within triangle_tol in both graphs. Applied only when there are >= prune_min_matches matches.
std::vector<Match> pruneMatches(const std::vector<Node>& query, const std::vector<Node>& candidate,
                                const std::vector<Match>& matches, const MatchConfig& config);

}  // namespace sglc
