// Hungarian assignment, descriptor matching and triangle pruning.
#include <gtest/gtest.h>

#include <unistd.h>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <numeric>
#include <random>
#include <set>

#include "sglc/matching.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

double assignmentCost(const Eigen::MatrixXd& cost, const std::vector<int>& a) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (a[i] >= 0) s += cost(static_cast<Eigen::Index>(i), a[i]);
  return s;
}

// Checks that `a` is a valid assignment: one entry per row, columns in range and distinct, and
// min(rows, cols) rows assigned.
void expectValidAssignment(const Eigen::MatrixXd& cost, const std::vector<int>& a) {
  ASSERT_EQ(a.size(), static_cast<std::size_t>(cost.rows()));
  std::set<int> cols;
  int assigned = 0;
  for (int c : a) {
    if (c < 0) continue;
    ++assigned;
    EXPECT_LT(c, cost.cols());
    EXPECT_TRUE(cols.insert(c).second) << "column " << c << " used twice";
  }
  EXPECT_EQ(assigned, std::min(cost.rows(), cost.cols()));
}

// Minimum total cost over all assignments of min(rows, cols) rows to distinct columns (brute force).
double bruteForceMin(const Eigen::MatrixXd& cost) {
  const bool tr = cost.rows() > cost.cols();
  const Eigen::MatrixXd a = tr ? Eigen::MatrixXd(cost.transpose()) : cost;  // rows <= cols
  std::vector<int> cols(a.cols());
  std::iota(cols.begin(), cols.end(), 0);
  double best = std::numeric_limits<double>::infinity();
  // Every ordering of the columns; the first a.rows() of them are the assignment.
  do {
    double s = 0;
    for (int i = 0; i < a.rows(); ++i) s += a(i, cols[i]);
    best = std::min(best, s);
  } while (std::next_permutation(cols.begin(), cols.end()));
  return best;
}

TEST(Hungarian, Square3x3KnownOptimum) {
  Eigen::MatrixXd c(3, 3);
  c << 4, 1, 3,  //
      2, 0, 5,   //
      3, 2, 2;
  // Hand enumeration of the 6 permutations: (1,0,2) costs 1 + 2 + 2 = 5, every other one is >= 6.
  EXPECT_EQ(hungarian(c), (std::vector<int>{1, 0, 2}));
}

TEST(Hungarian, Rectangular2x4) {
  Eigen::MatrixXd c(2, 4);
  c << 9, 2, 7, 8,  //
      6, 4, 3, 7;
  EXPECT_EQ(hungarian(c), (std::vector<int>{1, 2}));  // 2 + 3
}

TEST(Hungarian, Rectangular4x2) {
  Eigen::MatrixXd c(4, 2);
  c << 9, 6,  //
      2, 4,   //
      7, 3,   //
      8, 7;
  EXPECT_EQ(hungarian(c), (std::vector<int>{-1, 0, 1, -1}));  // 2 + 3, rows 0 and 3 unassigned
}

TEST(Hungarian, AllEqualCosts) {
  for (auto [r, c] : {std::pair{4, 4}, std::pair{3, 5}, std::pair{5, 3}}) {
    const Eigen::MatrixXd cost = Eigen::MatrixXd::Constant(r, c, 0.7);
    const auto a = hungarian(cost);
    expectValidAssignment(cost, a);
    EXPECT_NEAR(assignmentCost(cost, a), 0.7 * std::min(r, c), 1e-12);
  }
}

TEST(Hungarian, EmptyMatrices) {
  EXPECT_TRUE(hungarian(Eigen::MatrixXd(0, 0)).empty());
  EXPECT_TRUE(hungarian(Eigen::MatrixXd(0, 5)).empty());
  EXPECT_EQ(hungarian(Eigen::MatrixXd(3, 0)), (std::vector<int>{-1, -1, -1}));
  Eigen::MatrixXd one(1, 1);
  one << 42;
  EXPECT_EQ(hungarian(one), (std::vector<int>{0}));
}

TEST(Hungarian, NegativeAndForbiddenCosts) {
  Eigen::MatrixXd c(3, 3);
  c << -1, 1e8, 1e8,  //
      1e8, 1e8, -2,   //
      0.5, 1e8, 1e8;
  // Row 1 takes column 2 (-2). Rows 0 and 2 both want column 0 and one of them must take the forbidden column 1:
  // 0->0, 2->1 costs -1 + 1e8, 0->1, 2->0 costs 1e8 + 0.5, so the former.
  EXPECT_EQ(hungarian(c), (std::vector<int>{0, 2, 1}));
}

TEST(Hungarian, OptimalAgainstBruteForce) {
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> u(0.0, 10.0);
  std::uniform_int_distribution<int> small(0, 4);
  const std::pair<int, int> shapes[] = {{1, 1}, {2, 2}, {3, 3}, {4, 4}, {5, 5}, {6, 6}, {2, 5},
                                        {5, 2}, {3, 6}, {6, 3}, {4, 7}, {7, 4}, {1, 6}, {6, 1}};
  for (const auto& [r, c] : shapes)
    for (int trial = 0; trial < 8; ++trial) {
      Eigen::MatrixXd cost(r, c);
      for (int i = 0; i < r; ++i)
        for (int j = 0; j < c; ++j) cost(i, j) = trial % 2 ? u(rng) : small(rng);  // ties on odd trials
      const auto a = hungarian(cost);
      expectValidAssignment(cost, a);
      EXPECT_NEAR(assignmentCost(cost, a), bruteForceMin(cost), 1e-9) << r << "x" << c << "\n" << cost;
      EXPECT_EQ(hungarian(cost), a) << "not deterministic";
    }
}

// +inf is the usual way to forbid a pair. When some row has only forbidden entries (so every assignment costs
// +inf) the solver must still terminate with a valid assignment. Run in a child process with a 2 s alarm so a
// hang fails this test only.
TEST(HungarianDeathTest, InfiniteCostsTerminate) {
  const double inf = std::numeric_limits<double>::infinity();
  Eigen::MatrixXd c(2, 2);
  c << inf, inf,  //
      1, 2;
  EXPECT_EXIT(
      {
        alarm(2);
        const auto a = hungarian(c);
        const bool valid = a.size() == 2 && a[0] >= 0 && a[1] >= 0 && a[0] < 2 && a[1] < 2 && a[0] != a[1];
        std::exit(valid ? 0 : 1);
      },
      ::testing::ExitedWithCode(0), "")
      << "hungarian() on [[inf, inf], [1, 2]] did not return a valid assignment (signal 14 = hung)";
}

Node node(float x, float y, int cls, Vec3f size = Vec3f(1, 1, 1)) {
  Node n;
  n.center = Vec3f(x, y, 0);
  n.size = size;
  n.cls = static_cast<std::uint8_t>(cls);
  return n;
}

TEST(MatchNodes, ClassAndBoxGates) {
  const Vec3f car(4.0f, 1.8f, 1.5f), pole(0.3f, 0.3f, 5.0f);
  const std::vector<Node> q{node(0, 0, 0, car), node(5, 0, 2, pole), node(9, 9, 1, pole)};
  const std::vector<Node> c{
      node(0, 0, 2, pole),                            // 0: matches q1 (class 2)
      node(1, 0, 0, car + Vec3f(2.5f, 0, 0)),         // 1: class 0 but length differs by 2.5 > d_b
      node(2, 0, 0, car + Vec3f(1.5f, -1.0f, 0.5f)),  // 2: class 0, every dimension within d_b
      node(3, 0, 1, pole + Vec3f(0, 0, 2.2f)),        // 3: class 1, height differs by 2.2 > d_b
      node(4, 0, 1, pole),                            // 4: class 1 but dissimilar descriptor
  };
  // Descriptors: all the same except candidate 4, which is orthogonal to everything.
  Eigen::MatrixXf dq = Eigen::MatrixXf::Zero(3, 4), dc = Eigen::MatrixXf::Zero(5, 4);
  dq.col(0).setOnes();
  dc.col(0).setOnes();
  dc.row(4) << 0, 1, 0, 0;
  const auto m = matchNodes(q, dq, c, dc, MatchConfig{});
  EXPECT_EQ(m, (std::vector<Match>{{0, 2}, {1, 0}}));
  for (const auto& [i, j] : m) EXPECT_EQ(q[i].cls, c[j].cls);
}

TEST(MatchNodes, DifferentClassNeverMatchesEvenIfIdentical) {
  const std::vector<Node> q{node(0, 0, 0), node(1, 0, 1)};
  const std::vector<Node> c{node(0, 0, 1), node(1, 0, 2)};
  const Eigen::MatrixXf d = Eigen::MatrixXf::Ones(2, 8);
  const auto m = matchNodes(q, d, c, d, MatchConfig{});
  EXPECT_EQ(m, (std::vector<Match>{{1, 0}}));
}

TEST(MatchNodes, PicksMostSimilarAndRespectsMinCosine) {
  const std::vector<Node> q{node(0, 0, 0), node(1, 0, 0)};
  const std::vector<Node> c{node(0, 0, 0), node(1, 0, 0), node(2, 0, 0)};
  Eigen::MatrixXf dq(2, 3), dc(3, 3);
  dq << 1, 0, 0,  //
      0, 1, 0;
  dc << 0.6f, 0.8f, 0,       // cos with q0 0.6, with q1 0.8
      0.95f, 0.0f, 0.3122f,  // cos with q0 ~0.95
      0, 0.1f, 1.0f;         // cos with q1 ~0.0995
  EXPECT_EQ(matchNodes(q, dq, c, dc, MatchConfig{}), (std::vector<Match>{{0, 1}, {1, 0}}));
  MatchConfig strict;
  strict.min_cosine = 0.9;
  EXPECT_EQ(matchNodes(q, dq, c, dc, strict), (std::vector<Match>{{0, 1}}));
  EXPECT_TRUE(matchNodes({}, Eigen::MatrixXf(0, 3), c, dc, MatchConfig{}).empty());
  EXPECT_TRUE(matchNodes(q, dq, {}, Eigen::MatrixXf(0, 3), MatchConfig{}).empty());
}

// Independent brute-force statement of the pruning rule, used only to check the premises of the test data.
int agreeingTriangles(const std::vector<Node>& q, int i, const std::vector<Node>& c, int j, const MatchConfig& cfg) {
  auto tris = [&](const std::vector<Node>& nodes, int k) {
    std::vector<std::array<float, 3>> out;
    std::vector<int> nb;
    for (int o = 0; o < static_cast<int>(nodes.size()); ++o)
      if (o != k && (nodes[o].center - nodes[k].center).norm() < cfg.d_l) nb.push_back(o);
    for (std::size_t a = 0; a < nb.size(); ++a)
      for (std::size_t b = a + 1; b < nb.size(); ++b) {
        std::array<float, 3> s{(nodes[nb[a]].center - nodes[k].center).norm(),
                               (nodes[nb[b]].center - nodes[k].center).norm(),
                               (nodes[nb[a]].center - nodes[nb[b]].center).norm()};
        std::sort(s.begin(), s.end());
        out.push_back(s);
      }
    return out;
  };
  const auto tq = tris(q, i), tc = tris(c, j);
  int n = 0;
  for (const auto& t : tq)
    for (const auto& u : tc)
      if (std::abs(t[0] - u[0]) <= cfg.triangle_tol && std::abs(t[1] - u[1]) <= cfg.triangle_tol &&
          std::abs(t[2] - u[2]) <= cfg.triangle_tol) {
        ++n;
        break;
      }
  return n;
}

struct PruneData {
  std::vector<Node> query, candidate;
  std::vector<Match> truth, planted;
};

PruneData pruneData() {
  PruneData d;
  std::mt19937 rng(2024);
  std::uniform_real_distribution<double> u(-40.0, 40.0);
  for (int k = 0; k < 40; ++k) d.query.push_back(node(static_cast<float>(u(rng)), static_cast<float>(u(rng)), k % 3));
  // The candidate sees the same nodes from another pose: candidate = T^-1 * query.
  const Mat4d Tinv = test::makeT(63.0, 25.0, -12.0, 0.4).inverse();
  for (const auto& n : d.query) {
    Node m = n;
    m.center = test::apply(Tinv, n.center);
    d.candidate.push_back(m);
  }
  // Planted outliers: nodes 3<->17, 5<->28, 8<->33 and 11<->36 swapped.
  const std::set<int> swapped{3, 17, 5, 28, 8, 33, 11, 36};
  const std::pair<int, int> swaps[] = {{3, 17}, {5, 28}, {8, 33}, {11, 36}};
  for (int k = 0; k < 40; ++k)
    if (!swapped.count(k)) d.truth.emplace_back(k, k);
  for (auto [a, b] : swaps) {
    d.planted.emplace_back(a, b);
    d.planted.emplace_back(b, a);
  }
  return d;
}

TEST(PruneMatches, RemovesPlantedOutliersKeepsTrueMatches) {
  const PruneData d = pruneData();
  const MatchConfig cfg;
  std::vector<Match> all = d.truth;
  all.insert(all.end(), d.planted.begin(), d.planted.end());
  std::sort(all.begin(), all.end());
  ASSERT_GE(static_cast<int>(all.size()), cfg.prune_min_matches);
  // Premises of the data: every true match has >= t_m congruent local triangles, no planted one has.
  std::vector<Match> expected;
  for (const auto& [i, j] : all) {
    const int n = agreeingTriangles(d.query, i, d.candidate, j, cfg);
    const bool is_true = i == j;
    if (is_true) {
      // A node needs at least 3 neighbours within d_l for 2 triangles; the few that have fewer are not
      // expected to survive (that is the rule, not an outlier).
      if (n >= cfg.t_m) expected.emplace_back(i, j);
    } else {
      ASSERT_LT(n, cfg.t_m) << "planted outlier (" << i << "," << j << ") happens to be locally congruent";
    }
  }
  ASSERT_GE(expected.size(), d.truth.size() - 3) << "test layout too sparse";
  const auto kept = pruneMatches(d.query, d.candidate, all, cfg);
  EXPECT_EQ(kept, expected);
  for (const auto& p : d.planted) EXPECT_EQ(std::count(kept.begin(), kept.end(), p), 0) << p.first << "," << p.second;
}

TEST(PruneMatches, BelowMinMatchesNothingPruned) {
  const PruneData d = pruneData();
  const MatchConfig cfg;
  std::vector<Match> few(d.truth.begin(), d.truth.begin() + (cfg.prune_min_matches - 3));
  few.insert(few.end(), d.planted.begin(), d.planted.begin() + 2);
  ASSERT_LT(static_cast<int>(few.size()), cfg.prune_min_matches);
  EXPECT_EQ(pruneMatches(d.query, d.candidate, few, cfg), few);
  // And with prune_min_matches lowered to that count, the planted ones go.
  MatchConfig low = cfg;
  low.prune_min_matches = static_cast<int>(few.size());
  const auto kept = pruneMatches(d.query, d.candidate, few, low);
  for (int k = 0; k < 2; ++k) EXPECT_EQ(std::count(kept.begin(), kept.end(), d.planted[k]), 0);
}

TEST(PruneMatches, TriangleToleranceAndTm) {
  // A 4-node square of side 10 (3 triangles per node) and the same square stretched by 0.4 m along x.
  std::vector<Node> q{node(0, 0, 0), node(10, 0, 0), node(10, 10, 0), node(0, 10, 0)};
  std::vector<Node> c = q;
  for (auto& n : c) n.center.x() *= 1.04f;
  const std::vector<Match> m{{0, 0}, {1, 1}, {2, 2}, {3, 3}};
  MatchConfig cfg;
  cfg.prune_min_matches = 0;
  cfg.triangle_tol = 0.5;  // stretch of 0.4 m (diagonal 0.28 m) is within tolerance
  EXPECT_EQ(pruneMatches(q, c, m, cfg), m);
  cfg.triangle_tol = 0.2;  // the 10 m sides along x now differ by 0.4 > 0.2
  EXPECT_TRUE(pruneMatches(q, c, m, cfg).empty());
  cfg.triangle_tol = 0.5;
  cfg.t_m = 4;  // only 3 triangles per node
  EXPECT_TRUE(pruneMatches(q, c, m, cfg).empty());
  cfg.t_m = 3;
  EXPECT_EQ(pruneMatches(q, c, m, cfg), m);
}

}  // namespace
}  // namespace sglc
