#include "sglc/consensus.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

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
      if (!(cosine >= config.consensus_min_cosine)) continue;  // NaN fails too
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

// splitmix64, as RANSAC's sampler: a seeded order that is the same on every platform.
struct SplitMix {
  std::uint64_t state;
  std::uint64_t next() {
    std::uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
};

// Scores motions: how many candidates one motion aligns one-to-one, nearest first. Buffers are reused.
class Scorer {
 public:
  Scorer(const std::vector<Candidate>& pairs, const std::vector<Vec3d>& q, const std::vector<Vec3d>& c,
         double threshold)
      : pairs_(pairs), q_(q), c_(c), threshold_(threshold) {}

  // One-to-one inliers of T (greedy, nearest first; ties by index) and their residual sum; the count is
  // returned without the pairing when even the raw count cannot beat `to_beat`.
  int score(const Mat4d& T, int to_beat, double* sum) {
    const Mat3d R = T.topLeftCorner<3, 3>();
    const Vec3d t = T.topRightCorner<3, 1>();
    near_.clear();
    for (int k = 0; k < static_cast<int>(pairs_.size()); ++k)
      if (const double r = (R * c_[k] + t - q_[k]).norm(); r < threshold_) near_.emplace_back(r, k);
    if (static_cast<int>(near_.size()) < to_beat) return 0;
    std::sort(near_.begin(), near_.end());
    kept_.clear();
    *sum = 0;
    for (const auto& entry : near_) {
      const Candidate& next = pairs_[entry.second];
      const bool taken = std::any_of(kept_.begin(), kept_.end(),
                                     [&](int o) { return pairs_[o].i == next.i || pairs_[o].j == next.j; });
      if (taken) continue;
      kept_.push_back(entry.second);
      *sum += entry.first;
    }
    return static_cast<int>(kept_.size());
  }
  const std::vector<int>& kept() const { return kept_; }

 private:
  const std::vector<Candidate>& pairs_;
  const std::vector<Vec3d>& q_;
  const std::vector<Vec3d>& c_;
  double threshold_;
  std::vector<std::pair<double, int>> near_;
  std::vector<int> kept_;
};

// The most nodes any motion could align: distinct query nodes and distinct candidate nodes among the pairs.
int mostAlignable(const std::vector<Candidate>& pairs) {
  std::vector<int> is, js;
  for (const auto& p : pairs) {
    is.push_back(p.i);
    js.push_back(p.j);
  }
  for (auto* v : {&is, &js}) {
    std::sort(v->begin(), v->end());
    v->erase(std::unique(v->begin(), v->end()), v->end());
  }
  return static_cast<int>(std::min(is.size(), js.size()));
}

}  // namespace

bool consensusApplies(const MatchConfig& config, std::size_t query_nodes, std::size_t candidate_nodes) {
  return config.consensus_max_nodes > 0 &&
         std::min(query_nodes, candidate_nodes) <= static_cast<std::size_t>(config.consensus_max_nodes);
}

std::vector<Match> consensusMatches(const std::vector<Node>& query, const Eigen::MatrixXf& query_desc,
                                    const std::vector<Node>& candidate, const Eigen::MatrixXf& candidate_desc,
                                    const MatchConfig& match, const RansacConfig& ransac) {
  if (!consensusApplies(match, query.size(), candidate.size())) return {};
  const auto pairs = candidates(query, query_desc, candidate, candidate_desc, match);
  const auto n = pairs.size();  // <= consensus_max_nodes * consensus_per_node (64 * 32 at most)
  if (n < 3) return {};
  std::vector<Vec3d> q(n), c(n);
  for (std::size_t k = 0; k < n; ++k) {
    q[k] = query[pairs[k].i].center.cast<double>();
    c[k] = candidate[pairs[k].j].center.cast<double>();
  }
  // Two candidates agree when they use four distinct nodes and keep their distance (rigid motions do).
  const double tol = 2 * ransac.inlier_threshold;
  std::vector<char> agree(n * n, 0);
  std::vector<std::pair<int, int>> edges;
  for (std::size_t a = 0; a < n; ++a)
    for (std::size_t b = a + 1; b < n; ++b)
      if (pairs[a].i != pairs[b].i && pairs[a].j != pairs[b].j &&
          std::abs((q[a] - q[b]).norm() - (c[a] - c[b]).norm()) <= tol) {
        agree[a * n + b] = agree[b * n + a] = 1;
        edges.emplace_back(static_cast<int>(a), static_cast<int>(b));
      }
  // Edges in a seeded shuffled order, so that a budget spent early is not spent on the first nodes only.
  SplitMix rng{ransac.seed};
  for (std::size_t e = edges.size(); e > 1; --e) std::swap(edges[e - 1], edges[rng.next() % e]);
  Scorer scorer(pairs, q, c, ransac.inlier_threshold);
  const int ceiling = mostAlignable(pairs);
  int best_count = 0;
  double best_sum = std::numeric_limits<double>::max();
  Mat4d best_T = Mat4d::Identity();
  long long budget = match.consensus_max_hypotheses;  // every third candidate looked at counts, flat or not
  for (const auto& [a, b] : edges) {
    if (budget <= 0 || best_count >= ceiling) break;
    for (std::size_t k = static_cast<std::size_t>(b) + 1; k < n && budget > 0; ++k) {
      if (!agree[a * n + k] || !agree[b * n + k]) continue;
      --budget;
      if (smallestHeight(q[a], q[b], q[k]) < ransac.min_triangle_height ||
          smallestHeight(c[a], c[b], c[k]) < ransac.min_triangle_height)
        continue;
      const Mat4d T = fitRigid({c[a], c[b], c[k]}, {q[a], q[b], q[k]});
      double sum = 0;
      const int count = scorer.score(T, best_count, &sum);
      if (count > best_count || (count == best_count && count > 0 && sum < best_sum)) {
        best_count = count;
        best_sum = sum;
        best_T = T;
      }
    }
  }
  if (best_count < 3) return {};
  double sum = 0;
  scorer.score(best_T, 0, &sum);
  std::vector<Match> out;
  for (int k : scorer.kept()) out.emplace_back(pairs[k].i, pairs[k].j);
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace sglc
