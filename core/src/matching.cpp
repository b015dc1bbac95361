#include "sglc/matching.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace sglc {
namespace {

constexpr double kForbidden = 1e8;

// Sorted side lengths of the triangles a node forms with every pair of its neighbours within radius.
std::vector<std::array<float, 3>> localTriangles(const std::vector<Node>& nodes, int center, double radius) {
  const float r2 = static_cast<float>(radius * radius);
  std::vector<int> nb;
  for (int k = 0; k < static_cast<int>(nodes.size()); ++k)
    if (k != center && (nodes[k].center - nodes[center].center).squaredNorm() < r2) nb.push_back(k);
  std::vector<std::array<float, 3>> tris;
  tris.reserve(nb.size() * (nb.size() - (nb.empty() ? 0 : 1)) / 2);
  for (std::size_t a = 0; a < nb.size(); ++a)
    for (std::size_t b = a + 1; b < nb.size(); ++b) {
      std::array<float, 3> s{(nodes[nb[a]].center - nodes[center].center).norm(),
                             (nodes[nb[b]].center - nodes[center].center).norm(),
                             (nodes[nb[a]].center - nodes[nb[b]].center).norm()};
      std::sort(s.begin(), s.end());
      tris.push_back(s);
    }
  std::sort(tris.begin(), tris.end(), [](const auto& x, const auto& y) { return x[2] < y[2]; });
  return tris;
}

}  // namespace

std::vector<int> hungarian(const Eigen::MatrixXd& cost) {
  const int rows = static_cast<int>(cost.rows()), cols = static_cast<int>(cost.cols());
  if (rows == 0 || cols == 0) return std::vector<int>(rows, -1);
  const bool transposed = rows > cols;
  Eigen::MatrixXd a = transposed ? Eigen::MatrixXd(cost.transpose()) : cost;
  // Non-finite costs (the usual way to forbid a pair) become a large finite one, so potentials stay finite;
  // the caller sees forbidden pairs by their cost.
  double finite_max = 0;
  for (Eigen::Index k = 0; k < a.size(); ++k)
    if (std::isfinite(a.data()[k])) finite_max = std::max(finite_max, std::abs(a.data()[k]));
  const double big = (finite_max + 1.0) * static_cast<double>(a.rows() + 1);
  for (Eigen::Index k = 0; k < a.size(); ++k)
    if (!std::isfinite(a.data()[k])) a.data()[k] = big;
  const int n = static_cast<int>(a.rows()), m = static_cast<int>(a.cols());  // n <= m
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // Shortest augmenting paths with row/column potentials (u, v); column 0 is a virtual start.
  std::vector<double> u(n + 1, 0.0), v(m + 1, 0.0), min_slack(m + 1);
  std::vector<int> owner(m + 1, 0), prev(m + 1, 0);
  std::vector<char> visited(m + 1);
  for (int row = 1; row <= n; ++row) {
    owner[0] = row;
    int col = 0;
    std::fill(min_slack.begin(), min_slack.end(), kInf);
    std::fill(visited.begin(), visited.end(), 0);
    do {
      visited[col] = 1;
      const int r = owner[col];
      double delta = kInf;
      int next = 0;
      for (int j = 1; j <= m; ++j) {
        if (visited[j]) continue;
        const double slack = a(r - 1, j - 1) - u[r] - v[j];
        if (slack < min_slack[j]) {
          min_slack[j] = slack;
          prev[j] = col;
        }
        if (min_slack[j] < delta) {
          delta = min_slack[j];
          next = j;
        }
      }
      for (int j = 0; j <= m; ++j) {
        if (visited[j]) {
          u[owner[j]] += delta;
          v[j] -= delta;
        } else {
          min_slack[j] -= delta;
        }
      }
      col = next;
    } while (owner[col] != 0);
    do {  // flip the augmenting path
      const int p = prev[col];
      owner[col] = owner[p];
      col = p;
    } while (col != 0);
  }
  std::vector<int> row_to_col(n, -1);
  for (int j = 1; j <= m; ++j)
    if (owner[j] != 0) row_to_col[owner[j] - 1] = j - 1;
  if (!transposed) return row_to_col;
  std::vector<int> result(rows, -1);
  for (int i = 0; i < n; ++i)
    if (row_to_col[i] >= 0) result[row_to_col[i]] = i;
  return result;
}

std::vector<Match> matchNodes(const std::vector<Node>& query, const Eigen::MatrixXf& query_desc,
                              const std::vector<Node>& candidate, const Eigen::MatrixXf& candidate_desc,
                              const MatchConfig& config) {
  const int n = static_cast<int>(query.size()), m = static_cast<int>(candidate.size());
  if (n == 0 || m == 0) return {};
  const Eigen::VectorXf qn = query_desc.rowwise().norm(), cn = candidate_desc.rowwise().norm();
  const Eigen::MatrixXf dots = query_desc * candidate_desc.transpose();
  Eigen::MatrixXd cost = Eigen::MatrixXd::Constant(n, m, kForbidden);
  const float db = static_cast<float>(config.d_b);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j) {
      if (query[i].cls != candidate[j].cls) continue;
      if (((query[i].size - candidate[j].size).cwiseAbs().array() > db).any()) continue;
      const float denom = qn[i] * cn[j];
      const double cosine = denom > 0 ? dots(i, j) / denom : 0.0;
      if (cosine < config.min_cosine) continue;
      cost(i, j) = 1.0 - cosine;
    }
  const auto assignment = hungarian(cost);
  std::vector<Match> matches;
  for (int i = 0; i < n; ++i)
    if (assignment[i] >= 0 && cost(i, assignment[i]) < kForbidden) matches.emplace_back(i, assignment[i]);
  return matches;
}

std::vector<Match> pruneMatches(const std::vector<Node>& query, const std::vector<Node>& candidate,
                                const std::vector<Match>& matches, const MatchConfig& config) {
  if (static_cast<int>(matches.size()) < config.prune_min_matches) return matches;
  const float tol = static_cast<float>(config.triangle_tol);
  std::vector<Match> kept;
  for (const auto& [i, j] : matches) {
    const auto tq = localTriangles(query, i, config.d_l);
    const auto tc = localTriangles(candidate, j, config.d_l);
    int agreeing = 0;
    for (const auto& t : tq) {
      // tc is sorted by its longest side: only that window can agree.
      auto it = std::lower_bound(tc.begin(), tc.end(), t[2] - tol,
                                 [](const std::array<float, 3>& x, float v) { return x[2] < v; });
      for (; it != tc.end() && (*it)[2] <= t[2] + tol; ++it)
        if (std::abs((*it)[0] - t[0]) <= tol && std::abs((*it)[1] - t[1]) <= tol) {
          ++agreeing;
          break;
        }
      if (agreeing >= config.t_m) break;
    }
    if (agreeing >= config.t_m) kept.emplace_back(i, j);
  }
  return kept;
}

}  // namespace sglc
