#include "sglc/consensus.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "sglc/registration.hpp"

namespace sglc {
namespace {

struct Candidate {
  int i, j;      // query node, candidate node
  float cosine;  // descriptor similarity
};

// The triangle's smallest height: twice its area over its longest side (0 for a degenerate one).
double smallestHeight(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const double longest = std::max({(a - b).norm(), (b - c).norm(), (c - a).norm()});
  return longest > 0 ? (b - a).cross(c - a).norm() / longest : 0.0;
}

double cosineOf(const Eigen::MatrixXf& a, int i, const Eigen::MatrixXf& b, int j) {
  const float denom = a.row(i).norm() * b.row(j).norm();
  return denom > 0 ? a.row(i).dot(b.row(j)) / denom : 0.0;
}

// The compatible pairs, the smaller graph's nodes keeping their most similar partners only.
std::vector<Candidate> candidates(const std::vector<Node>& query, const Eigen::MatrixXf& query_desc,
                                  const std::vector<Node>& candidate, const Eigen::MatrixXf& candidate_desc,
                                  const MatchConfig& config) {
  const bool by_query = query.size() <= candidate.size();
  const int outer = static_cast<int>(by_query ? query.size() : candidate.size());
  const int inner = static_cast<int>(by_query ? candidate.size() : query.size());
  const auto db = static_cast<float>(config.d_b);
  std::vector<Candidate> out;
  std::vector<Candidate> own;
  for (int u = 0; u < outer; ++u) {
    own.clear();
    for (int v = 0; v < inner; ++v) {
      const int i = by_query ? u : v, j = by_query ? v : u;
      if (query[i].cls != candidate[j].cls) continue;
      if (((query[i].size - candidate[j].size).cwiseAbs().array() > db).any()) continue;
      const double cosine = cosineOf(query_desc, i, candidate_desc, j);
      if (cosine < config.consensus_min_cosine) continue;
      own.push_back({i, j, static_cast<float>(cosine)});
    }
    // Most similar first; equal cosines keep their index order, so the choice never varies.
    std::stable_sort(own.begin(), own.end(),
                     [](const Candidate& x, const Candidate& y) { return x.cosine > y.cosine; });
    if (static_cast<int>(own.size()) > config.consensus_per_node) own.resize(config.consensus_per_node);
    out.insert(out.end(), own.begin(), own.end());
  }
  return out;
}

// Residuals of every candidate under T, and the one-to-one inliers taken greedily, nearest first.
std::vector<int> oneToOneInliers(const std::vector<Candidate>& pairs, const std::vector<Vec3d>& q,
                                 const std::vector<Vec3d>& c, const Mat4d& T, double threshold, double* sum) {
  const Mat3d R = T.topLeftCorner<3, 3>();
  const Vec3d t = T.topRightCorner<3, 1>();
  std::vector<std::pair<double, int>> near;
  for (int k = 0; k < static_cast<int>(pairs.size()); ++k)
    if (const double r = (R * c[k] + t - q[k]).norm(); r < threshold) near.emplace_back(r, k);
  std::sort(near.begin(), near.end());
  std::vector<int> kept;
  *sum = 0;
  for (const auto& entry : near) {
    const Candidate& next = pairs[entry.second];
    const bool taken =
        std::any_of(kept.begin(), kept.end(), [&](int o) { return pairs[o].i == next.i || pairs[o].j == next.j; });
    if (taken) continue;
    kept.push_back(entry.second);
    *sum += entry.first;
  }
  return kept;
}

}  // namespace

bool consensusApplies(const MatchConfig& config, std::size_t query_nodes, std::size_t candidate_nodes) {
  return config.consensus_max_nodes > 0 &&
         std::min(query_nodes, candidate_nodes) <= static_cast<std::size_t>(config.consensus_max_nodes);
}

std::vector<Match> consensusMatches(const std::vector<Node>& query, const Eigen::MatrixXf& query_desc,
                                    const std::vector<Node>& candidate, const Eigen::MatrixXf& candidate_desc,
                                    const MatchConfig& match, const RansacConfig& ransac) {
  const auto pairs = candidates(query, query_desc, candidate, candidate_desc, match);
  const int n = static_cast<int>(pairs.size());
  if (n < 3) return {};
  std::vector<Vec3d> q(n), c(n);
  for (int k = 0; k < n; ++k) {
    q[k] = query[pairs[k].i].center.cast<double>();
    c[k] = candidate[pairs[k].j].center.cast<double>();
  }
  // Two candidates agree when they use four distinct nodes and keep their distance (rigid motions do).
  const double tol = 2 * ransac.inlier_threshold;
  std::vector<char> agree(static_cast<std::size_t>(n) * n, 0);
  for (int a = 0; a < n; ++a)
    for (int b = a + 1; b < n; ++b)
      if (pairs[a].i != pairs[b].i && pairs[a].j != pairs[b].j &&
          std::abs((q[a] - q[b]).norm() - (c[a] - c[b]).norm()) <= tol)
        agree[a * n + b] = agree[b * n + a] = 1;
  int best_count = 0, hypotheses = 0;
  double best_sum = std::numeric_limits<double>::max();
  Mat4d best_T = Mat4d::Identity();
  for (int a = 0; a < n && hypotheses < match.consensus_max_hypotheses; ++a)
    for (int b = a + 1; b < n && hypotheses < match.consensus_max_hypotheses; ++b) {
      if (!agree[a * n + b]) continue;
      for (int k = b + 1; k < n && hypotheses < match.consensus_max_hypotheses; ++k) {
        if (!agree[a * n + k] || !agree[b * n + k]) continue;
        if (smallestHeight(q[a], q[b], q[k]) < ransac.min_triangle_height ||
            smallestHeight(c[a], c[b], c[k]) < ransac.min_triangle_height)
          continue;
        ++hypotheses;
        const Mat4d T = fitRigid({c[a], c[b], c[k]}, {q[a], q[b], q[k]});
        double sum = 0;
        const int count = static_cast<int>(oneToOneInliers(pairs, q, c, T, ransac.inlier_threshold, &sum).size());
        if (count > best_count || (count == best_count && sum < best_sum)) {
          best_count = count;
          best_sum = sum;
          best_T = T;
        }
      }
    }
  if (best_count < 3) return {};
  double sum = 0;
  std::vector<Match> out;
  for (int k : oneToOneInliers(pairs, q, c, best_T, ransac.inlier_threshold, &sum))
    out.emplace_back(pairs[k].i, pairs[k].j);
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace sglc
