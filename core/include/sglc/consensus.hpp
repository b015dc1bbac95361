// Node correspondences found by geometry rather than by descriptors, for graphs too small for descriptors.
#pragma once

#include <vector>

#include "sglc/config.hpp"
#include "sglc/graph.hpp"
#include "sglc/matching.hpp"

namespace sglc {

// Whether consensus matching applies: one of the two graphs has at most match.consensus_max_nodes nodes
// (and the option is on). A node's descriptor summarises its neighbours; with a handful of nodes, as a
// 16- or 32-beam sensor sees, one neighbour more or less changes it wholesale, and the one-to-one assignment
// on descriptor costs then pairs the wrong nodes.
bool consensusApplies(const MatchConfig& config, std::size_t query_nodes, std::size_t candidate_nodes);

// Candidates: node pairs of equal class whose box dimensions differ by <= d_b and whose descriptor cosine is
// >= consensus_min_cosine; each node of the smaller graph keeps its consensus_per_node most similar. Two
// candidates agree when they use four distinct nodes and keep their distance within 2 * inlier_threshold;
// every triple of mutually agreeing candidates that is not flat proposes a rigid motion. Triples are visited
// through their agreeing pairs in an order shuffled by ransac.seed, at most consensus_max_hypotheses of them
// (flat ones count), stopping early once a motion aligns every node it could. The motion that aligns most
// nodes one-to-one within inlier_threshold (greedy, nearest first; ties: smaller residual sum) wins. Returns
// that set, sorted by query node, for RANSAC and the usual verification; empty when consensus does not
// apply (consensusApplies) or no triple agrees. Deterministic on every platform.
std::vector<Match> consensusMatches(const std::vector<Node>& query, const Eigen::MatrixXf& query_desc,
                                    const std::vector<Node>& candidate, const Eigen::MatrixXf& candidate_desc,
                                    const MatchConfig& match, const RansacConfig& ransac);

}  // namespace sglc
