// Node descriptors (local histogram + spectral part) and the scan descriptor.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <numeric>
#include <random>
#include <set>

#include "sglc/descriptors.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

Node node(float x, float y, float z, int cls) {
  Node n;
  n.center = Vec3f(x, y, z);
  n.size = Vec3f(1, 1, 1);
  n.cls = static_cast<std::uint8_t>(cls);
  return n;
}

DescriptorLayout layoutFor(int classes, double d_max, double d_i = 2.0) {
  GraphConfig g;
  g.d_max = d_max;
  DescriptorConfig d;
  d.d_i = d_i;
  return descriptorLayout(classes, g, d);
}

TEST(Descriptors, LayoutSizes) {
  const DescriptorLayout l = descriptorLayout(3, GraphConfig{}, DescriptorConfig{});
  EXPECT_EQ(l.bins, 30);  // 60 / 2
  EXPECT_EQ(l.k_eigen, 30);
  EXPECT_EQ(l.rings, 8);
  EXPECT_EQ(l.orders, 2);
  EXPECT_EQ(l.nodeDim(), 120);  // 3 * 30 + 30 (paper: D = 120)
  EXPECT_EQ(l.edgeTypes(), 6);
  EXPECT_EQ(l.spectrumDim(), 48);  // 2 parts * 8 rings * orders 0-2
  EXPECT_EQ(l.scanDim(), 231);     // 3 + 6 * 30 + 48 (paper: D' = 231, with a ring key of 48)
  // Bins round up when d_max is not a multiple of d_i.
  EXPECT_EQ(layoutFor(3, 61.0).bins, 31);
  EXPECT_EQ(layoutFor(3, 10.0).bins, 5);
  EXPECT_EQ(layoutFor(2, 60.0).edgeTypes(), 3);
  EXPECT_EQ(layoutFor(2, 60.0).scanDim(), 2 + 3 * 30 + 48);
}

TEST(Descriptors, EdgeTypeUniqueAndSymmetric) {
  for (int C : {1, 2, 3, 4, 7, 16}) {
    std::set<int> seen;
    for (int a = 0; a < C; ++a)
      for (int b = a; b < C; ++b) {
        const int t = edgeType(a, b, C);
        EXPECT_EQ(t, edgeType(b, a, C)) << a << "," << b;
        EXPECT_GE(t, 0);
        EXPECT_LT(t, C * (C + 1) / 2);
        EXPECT_TRUE(seen.insert(t).second) << "duplicate type " << t << " for " << a << "," << b << " C=" << C;
      }
    EXPECT_EQ(static_cast<int>(seen.size()), C * (C + 1) / 2);
  }
  // 3 classes: exactly 0..5.
  std::set<int> three;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) three.insert(edgeType(a, b, 3));
  EXPECT_EQ(three, (std::set<int>{0, 1, 2, 3, 4, 5}));
}

// Hand-checked: 3 nodes of classes 0, 1, 2; d_max 60, d_i 2 (30 bins per class, bin k centred on (k + 0.5) d_i).
// A count is shared between the two nearest bin centres (soft binning):
//   node 0 (0,0,0) cls 0 -- node 1 (5,0,0) cls 1: d = 5     -> on bin 2's centre: all in bin 2
//   node 0             -- node 2 (0,13,0) cls 2: d = 13    -> on bin 6's centre: all in bin 6
//   node 1             -- node 2:               d = 13.93 -> 6.464 bin widths: 0.536 in bin 6, 0.464 in bin 7
// Each row counts the NEIGHBOUR's class; the square roots of the counts are L2-normalised.
TEST(Descriptors, LocalPartCountsNeighbourClass) {
  const std::vector<Node> nodes{node(0, 0, 0, 0), node(5, 0, 0, 1), node(0, 13, 0, 2)};
  const DescriptorLayout l = layoutFor(3, 60.0);
  const Eigen::MatrixXf f = nodeDescriptors(nodes, l, 60.0, 2.0);
  ASSERT_EQ(f.rows(), 3);
  ASSERT_EQ(f.cols(), 120);
  const float h = 1.0f / std::sqrt(2.0f);
  const float w = static_cast<float>(std::sqrt(25.0 + 169.0) / 2.0 - 0.5 - 6.0);  // share of bin 7
  ASSERT_NEAR(w, 0.464, 0.001);
  Eigen::MatrixXf expected = Eigen::MatrixXf::Zero(3, 90);
  expected(0, 1 * 30 + 2) = h;
  expected(0, 2 * 30 + 6) = h;
  expected(1, 0 * 30 + 2) = h;  // sqrt(1), sqrt(1 - w), sqrt(w) have squares summing to 2
  expected(1, 2 * 30 + 6) = std::sqrt(1.0f - w) * h;
  expected(1, 2 * 30 + 7) = std::sqrt(w) * h;
  expected(2, 0 * 30 + 6) = h;
  expected(2, 1 * 30 + 6) = std::sqrt(1.0f - w) * h;
  expected(2, 1 * 30 + 7) = std::sqrt(w) * h;
  EXPECT_TRUE(f.leftCols(90).isApprox(expected, 1e-5f)) << f.leftCols(90);
}

// Soft binning moves weight smoothly: a neighbour walking from one bin centre to the next hands its count
// over linearly, with no jump at the bin edge (hard bins would flip the whole count there).
TEST(Descriptors, LocalPartMovesSmoothlyWithDistance) {
  const DescriptorLayout l = layoutFor(2, 60.0);
  Eigen::RowVectorXf previous;
  for (double d = 9.0; d <= 11.0 + 1e-9; d += 0.1) {  // bin 4's centre to bin 5's
    const Eigen::MatrixXf f = nodeDescriptors({node(0, 0, 0, 0), node(d, 0, 0, 1)}, l, 60.0, 2.0);
    const float a = f(0, 30 + 4), b = f(0, 30 + 5);
    const double share = (d - 9.0) / 2.0;
    EXPECT_NEAR(a * a, 1.0 - share, 1e-4) << d;  // squares of the normalised square roots = the shares
    EXPECT_NEAR(b * b, share, 1e-4) << d;
    if (previous.size() > 0) EXPECT_LT((f.row(0).head(60) - previous).norm(), 0.25f) << d;
    previous = f.row(0).head(60);
  }
}

// A crowd in one bin: node 0 has four neighbours of class 1 at 5 m (bin 2) and one of class 2 at 13 m (bin 6).
// Counts 4 and 1 enter as their square roots 2 and 1, so the crowd weighs 2/sqrt(5) and the loner 1/sqrt(5)
// (raw counts would give 4/sqrt(17) and 1/sqrt(17)).
TEST(Descriptors, LocalPartDampsCrowdedBins) {
  std::vector<Node> nodes{node(0, 0, 0, 0)};
  for (int k = 0; k < 4; ++k) nodes.push_back(node(5.0 * std::cos(0.3 * k), 5.0 * std::sin(0.3 * k), 0, 1));
  nodes.push_back(node(0, -13, 0, 2));
  const Eigen::MatrixXf f = nodeDescriptors(nodes, layoutFor(3, 60.0), 60.0, 2.0);
  EXPECT_NEAR(f(0, 1 * 30 + 2), 2.0 / std::sqrt(5.0), 1e-6);
  EXPECT_NEAR(f(0, 2 * 30 + 6), 1.0 / std::sqrt(5.0), 1e-6);
  EXPECT_NEAR(f.row(0).head(90).norm(), 1.0, 1e-6);
}

TEST(Descriptors, LocalPartDistanceCapAndLastBin) {
  // d = 59 -> last bin (29); d = 61 >= d_max -> no entry.
  const std::vector<Node> nodes{node(0, 0, 0, 0), node(59, 0, 0, 0), node(-61, 0, 0, 0)};
  const Eigen::MatrixXf f = nodeDescriptors(nodes, layoutFor(3, 60.0), 60.0, 2.0);
  EXPECT_FLOAT_EQ(f(0, 29), 1.0f);
  EXPECT_FLOAT_EQ(f.row(0).head(90).sum(), 1.0f);
  EXPECT_FLOAT_EQ(f.row(2).head(90).norm(), 0.0f);  // node 2 has no neighbour within d_max
}

// Hand-checked spectral part: a path 0 - 1 - 2 (d_max 8: 0-1 and 1-2 are 5 m apart, 0-2 10 m).
// A = I + path adjacency has eigenvalues 1+sqrt2, 1, 1-sqrt2 with eigenvectors (1/2, 1/sqrt2, 1/2),
// (1/sqrt2, 0, -1/sqrt2), (1/2, -1/sqrt2, 1/2). Row i of f_g = |eigenvector entries| (largest eigenvalue
// first), L1-normalised.
TEST(Descriptors, SpectralPartHandChecked) {
  const std::vector<Node> nodes{node(0, 0, 0, 0), node(5, 0, 0, 0), node(10, 0, 0, 0)};
  const DescriptorLayout l = layoutFor(3, 8.0);  // 4 bins -> local part 12, then 30 spectral columns
  const Eigen::MatrixXf f = nodeDescriptors(nodes, l, 8.0, 2.0);
  ASSERT_EQ(f.cols(), 12 + 30);
  const double r0 = 0.5 + std::sqrt(0.5) + 0.5;  // row 0: 1/2, 1/sqrt2, 1/2
  const Eigen::Vector3d row0(0.5 / r0, std::sqrt(0.5) / r0, 0.5 / r0);
  const Eigen::Vector3d row1(0.5, 0.0, 0.5);  // row 1: 1/sqrt2, 0, 1/sqrt2 over sqrt2
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(f(0, 12 + c), row0[c], 1e-6) << c;
    EXPECT_NEAR(f(1, 12 + c), row1[c], 1e-6) << c;
    EXPECT_NEAR(f(2, 12 + c), row0[c], 1e-6) << c;
  }
  // Fewer nodes than k_eigen: the remaining spectral columns are zero.
  EXPECT_EQ(f.rightCols(27).norm(), 0.0f);
  // Local part: node 1 has two class-0 neighbours at 5 m (bin 2) -> a single entry of 1 after L2.
  EXPECT_FLOAT_EQ(f(1, 2), 1.0f);
  EXPECT_FLOAT_EQ(f(0, 2), 1.0f);
}

// Random layout whose pairwise distances all stay clear of bin edges and of d_max (so float rounding under a
// rigid motion cannot move a distance across a boundary).
std::vector<Node> randomLayout(int n, std::uint32_t seed, double d_max, double d_i) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-45.0, 45.0), uz(-1.5, 1.5);
  std::vector<Node> nodes;
  while (static_cast<int>(nodes.size()) < n) {
    Node c = node(static_cast<float>(u(rng)), static_cast<float>(u(rng)), static_cast<float>(uz(rng)),
                  static_cast<int>(nodes.size() % 3));
    bool ok = true;
    for (const auto& o : nodes) {
      const double d = (o.center - c.center).cast<double>().norm();
      const double frac = d / d_i - std::floor(d / d_i);
      if (frac < 1e-3 || frac > 1 - 1e-3 || std::abs(d - d_max) < 1e-2 || d < 1.0) ok = false;
    }
    if (ok) nodes.push_back(c);
  }
  return nodes;
}

std::vector<Node> moved(const std::vector<Node>& nodes, const Mat4d& T) {
  std::vector<Node> out = nodes;
  for (auto& n : out) n.center = test::apply(T, n.center);
  return out;
}

// Rigid motion (yaw + translation, node order unchanged). The adjacency matrix is a 0/1 matrix of the
// (unchanged) distance relation, so it is bitwise identical after the motion and the spectral part cannot
// suffer from eigenvector sign/order ambiguity here, even if eigenvalues repeat (they usually do in dense
// geometric graphs: "twin" nodes give repeated eigenvalue 0). The test with a permutation below uses a
// layout with distinct eigenvalues.
TEST(Descriptors, NodeDescriptorsInvariantToRigidMotion) {
  const auto nodes = randomLayout(40, 11, 60.0, 2.0);
  const DescriptorLayout l = layoutFor(3, 60.0);
  const Eigen::MatrixXf f = nodeDescriptors(nodes, l, 60.0, 2.0);
  for (const Mat4d& T : {test::makeT(37.0, 120.0, -55.5, 2.0), test::makeT(-143.0, -3.0, 900.0, -1.0),
                         test::makeT(90.0, 0.0, 0.0, 0.0)}) {
    const auto m = moved(nodes, T);
    ASSERT_EQ(adjacency(m, 60.0), adjacency(nodes, 60.0));
    const Eigen::MatrixXf g = nodeDescriptors(m, l, 60.0, 2.0);
    ASSERT_EQ(g.rows(), f.rows());
    // Distances after the motion differ from the originals by float rounding; a neighbour on a bin centre then
    // has a share of ~1e-7 in the next bin, which the square root lifts to ~3e-4.
    EXPECT_LT((g - f).cwiseAbs().maxCoeff(), 1e-3f);
  }
}

// A zig-zag path (consecutive nodes 7 m apart, all others > 12 m; d_max 10): the adjacency is I + a path
// matrix whose eigenvalues 1 + 2 cos(k pi / (n+1)) are all distinct, so each eigenvector is unique up to sign
// and |eigenvector| rows must follow the nodes through a permutation.
TEST(Descriptors, NodeDescriptorsFollowPermutationAndMotion) {
  const int n = 9;
  std::vector<Node> path;
  Vec3f p(0, 0, 0);
  for (int k = 0; k < n; ++k) {
    path.push_back(node(p.x(), p.y(), p.z(), k % 3));
    const double a = test::deg2rad(k % 2 ? -30.0 : 30.0);
    p += Vec3f(static_cast<float>(7 * std::cos(a)), static_cast<float>(7 * std::sin(a)), 0);
  }
  const Eigen::MatrixXd A = adjacency(path, 10.0);
  // Independent check of the premise: path adjacency with distinct eigenvalues.
  ASSERT_EQ(A.sum(), n + 2.0 * (n - 1));
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(A).eigenvalues();
  for (int k = 1; k < n; ++k) ASSERT_GT(ev[k] - ev[k - 1], 0.1);

  const DescriptorLayout l = layoutFor(3, 10.0);
  const Eigen::MatrixXf f = nodeDescriptors(path, l, 10.0, 2.0);
  std::vector<int> perm(n);
  std::iota(perm.begin(), perm.end(), 0);
  std::mt19937 rng(5);
  std::shuffle(perm.begin(), perm.end(), rng);
  const Mat4d T = test::makeT(-71.0, 15.0, 22.0, 0.5);
  std::vector<Node> q(n);
  for (int k = 0; k < n; ++k) q[k] = path[perm[k]];  // q[k] is path node perm[k]
  q = moved(q, T);
  const Eigen::MatrixXf g = nodeDescriptors(q, l, 10.0, 2.0);
  // 1e-3: float rounding of distances that sit on a bin centre, lifted by the square root (see above).
  for (int k = 0; k < n; ++k) EXPECT_LT((g.row(k) - f.row(perm[k])).cwiseAbs().maxCoeff(), 1e-3f) << "node " << perm[k];
}

TEST(Descriptors, NodeDescriptorsNormalised) {
  const auto nodes = randomLayout(25, 2, 60.0, 2.0);
  const DescriptorLayout l = layoutFor(3, 60.0);
  const Eigen::MatrixXf f = nodeDescriptors(nodes, l, 60.0, 2.0);
  for (int i = 0; i < f.rows(); ++i) {
    ASSERT_TRUE(f.row(i).allFinite());
    const float local = f.row(i).head(90).norm();
    EXPECT_TRUE(std::abs(local - 1.0f) < 1e-5f || local == 0.0f) << i;
    EXPECT_NEAR(f.row(i).tail(30).sum(), 1.0f, 1e-5f) << i;  // L1 of non-negative values
    EXPECT_GE(f.row(i).minCoeff(), 0.0f);
  }
}

TEST(Descriptors, EmptyAndSingleNode) {
  const DescriptorLayout l = layoutFor(3, 60.0);
  const Eigen::MatrixXf f0 = nodeDescriptors({}, l, 60.0, 2.0);
  EXPECT_EQ(f0.rows(), 0);
  EXPECT_EQ(f0.cols(), 120);
  const Eigen::MatrixXf f1 = nodeDescriptors({node(3, 4, 0, 1)}, l, 60.0, 2.0);
  ASSERT_EQ(f1.rows(), 1);
  EXPECT_TRUE(f1.allFinite());
  EXPECT_EQ(f1.row(0).head(90).norm(), 0.0f);  // no neighbour
  EXPECT_FLOAT_EQ(f1(0, 90), 1.0f);            // the single eigenvector is (1)
}

TEST(Descriptors, ScanDescriptorUnitNormAndFinite) {
  const DescriptorLayout l = layoutFor(3, 60.0);
  const auto nodes = randomLayout(30, 4, 60.0, 2.0);
  std::vector<float> ring(48, 0.0f);
  for (int k = 0; k < 48; k += 3) ring[k] = static_cast<float>(k + 1);
  for (const double weight : {1.0, 3.0}) {
    const auto d = scanDescriptor(nodes, ring, l, 60.0, 2.0, weight);
    ASSERT_EQ(static_cast<int>(d.size()), 231);
    double norm = 0;
    for (float v : d) {
      ASSERT_TRUE(std::isfinite(v));
      EXPECT_GE(v, 0.0f);
      norm += double(v) * v;
    }
    EXPECT_NEAR(std::sqrt(norm), 1.0, 1e-5);
    // Graph and background parts are each L2-normalised, the background one then weighted: the graph part
    // carries 1 / (1 + weight^2) of the energy.
    double g = 0;
    for (int k = 0; k < 183; ++k) g += double(d[k]) * d[k];
    EXPECT_NEAR(g, 1.0 / (1.0 + weight * weight), 1e-5) << weight;
  }
}

TEST(Descriptors, ScanDescriptorHandChecked) {
  // Two class-0 nodes 5 m apart and one class-2 node 13 m from the first, hypot(5, 13) = 13.93 m from the
  // second; no ring key. Edges are soft-binned: 5 m and 13 m sit on the centres of bins 2 and 6, 13.93 m
  // shares its count between bins 6 and 7.
  const std::vector<Node> nodes{node(0, 0, 0, 0), node(5, 0, 0, 0), node(0, 13, 0, 2)};
  const DescriptorLayout l = layoutFor(3, 60.0);
  const auto d = scanDescriptor(nodes, std::vector<float>(48, 0.0f), l, 60.0, 2.0, 3.0);
  ASSERT_EQ(d.size(), 231u);
  const double w = std::hypot(5.0, 13.0) / 2.0 - 0.5 - 6.0;  // 0.465: bin 7's share
  // counts (2, 0, 1) / sqrt5; edges: type(0,0)=0 bin 2: 1; type(0,2)=2 bin 6: 1 + (1 - w), bin 7: w.
  // fg = [counts | edges] has norm sqrt2 -> each / sqrt2; spectrum zero -> stays zero, whatever its weight.
  const double ne = std::sqrt(1.0 + (2.0 - w) * (2.0 - w) + w * w);
  const double kc = 1.0 / std::sqrt(5.0) / std::sqrt(2.0), ke = 1.0 / ne / std::sqrt(2.0);
  std::vector<double> expected(231, 0.0);
  expected[0] = 2 * kc;
  expected[2] = 1 * kc;
  expected[3 + 0 * 30 + 2] = 1 * ke;
  expected[3 + 2 * 30 + 6] = (2.0 - w) * ke;
  expected[3 + 2 * 30 + 7] = w * ke;
  for (int i = 0; i < 231; ++i) EXPECT_NEAR(d[i], expected[i], 1e-6) << i;
}

// Moving one node a little moves the scan descriptor a little: no jump where a distance crosses a bin edge.
TEST(Descriptors, ScanDescriptorMovesSmoothlyWithDistance) {
  const DescriptorLayout l = layoutFor(2, 60.0);
  std::vector<float> previous;
  for (double d = 9.0; d <= 11.0 + 1e-9; d += 0.1) {  // across the edge between bins 4 and 5 at 10 m
    const auto now =
        scanDescriptor({node(0, 0, 0, 0), node(d, 0, 0, 1)}, std::vector<float>(48, 0.0f), l, 60.0, 2.0, 3.0);
    if (!previous.empty()) {
      double step = 0;
      for (std::size_t k = 0; k < now.size(); ++k) step += (now[k] - previous[k]) * (now[k] - previous[k]);
      EXPECT_LT(std::sqrt(step), 0.1) << d;
    }
    previous = now;
  }
}

TEST(Descriptors, ScanDescriptorZeroSpectrumNoNaN) {
  const DescriptorLayout l = layoutFor(3, 60.0);
  const auto d = scanDescriptor(randomLayout(10, 9, 60.0, 2.0), std::vector<float>(48, 0.0f), l, 60.0, 2.0, 3.0);
  double norm = 0;
  for (float v : d) {
    ASSERT_TRUE(std::isfinite(v));
    norm += double(v) * v;
  }
  EXPECT_NEAR(norm, 1.0, 1e-5);
  for (int k = 183; k < 231; ++k) EXPECT_EQ(d[k], 0.0f);
}

TEST(Descriptors, ScanDescriptorEmptyNodes) {
  const DescriptorLayout l = layoutFor(3, 60.0);
  const auto none = scanDescriptor({}, std::vector<float>(48, 0.0f), l, 60.0, 2.0, 3.0);
  ASSERT_EQ(none.size(), 231u);
  for (float v : none) EXPECT_TRUE(std::isfinite(v));
  // With a spectrum only the background part is non-zero, and the whole is unit norm.
  std::vector<float> ring(48, 0.0f);
  ring[5] = 3;
  ring[30] = 4;
  const auto bg = scanDescriptor({}, ring, l, 60.0, 2.0, 3.0);
  for (int k = 0; k < 183; ++k) EXPECT_EQ(bg[k], 0.0f);
  EXPECT_NEAR(bg[183 + 5], 0.6, 1e-6);
  EXPECT_NEAR(bg[183 + 30], 0.8, 1e-6);
}

TEST(Descriptors, ScanDescriptorInvariantToRigidMotion) {
  const DescriptorLayout l = layoutFor(3, 60.0);
  const auto nodes = randomLayout(30, 21, 60.0, 2.0);
  std::vector<float> ring(48, 0.1f);
  const auto a = scanDescriptor(nodes, ring, l, 60.0, 2.0, 3.0);
  const auto b = scanDescriptor(moved(nodes, test::makeT(123.0, -40.0, 17.0, 1.0)), ring, l, 60.0, 2.0, 3.0);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k) EXPECT_NEAR(a[k], b[k], 1e-6) << k;
}

}  // namespace
}  // namespace sglc
