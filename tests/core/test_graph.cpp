// Nodes (yaw-invariant boxes), node selection and the adjacency matrix.
#include <gtest/gtest.h>

#include <numeric>

#include "sglc/graph.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::deg2rad;

// A filled horizontal rectangle (length 4, width 1.6) in 3 layers z = -1.0, -0.25, 0.5, centred at c and
// rotated by yaw about its own centre.
Points rectangle(const Vec3d& c, double yaw_deg) {
  Points pts;
  const Mat3d R = Eigen::AngleAxisd(deg2rad(yaw_deg), Vec3d::UnitZ()).toRotationMatrix();
  for (int i = 0; i <= 40; ++i)
    for (int j = 0; j <= 16; ++j)
      for (double z : {-0.75, 0.0, 0.75}) {
        const Vec3d local(-2.0 + 0.1 * i, -0.8 + 0.1 * j, z);
        pts.push_back((c + R * local).cast<float>());
      }
  return pts;
}

Cluster all(const Points& pts, int cls) {
  Cluster c;
  c.cls = cls;
  c.points.resize(pts.size());
  std::iota(c.points.begin(), c.points.end(), 0u);
  return c;
}

TEST(Graph, MakeNodeBoxOfRectangle) {
  const Vec3d c(12.0, -5.0, -0.5);
  const Points pts = rectangle(c, 0.0);
  const Node n = makeNode(pts, all(pts, 1));
  EXPECT_NEAR(n.size.x(), 4.0, 1e-4);
  EXPECT_NEAR(n.size.y(), 1.6, 1e-4);
  EXPECT_NEAR(n.size.z(), 1.5, 1e-5);
  EXPECT_NEAR((n.center.cast<double>() - c).norm(), 0.0, 1e-4);
  EXPECT_EQ(n.cls, 1);
}

TEST(Graph, MakeNodeSizeInvariantToYaw) {
  const Vec3d c(-7.0, 20.0, 0.3);
  const Node ref = makeNode(rectangle(c, 0.0), all(rectangle(c, 0.0), 0));
  for (double yaw : {10.0, 33.0, 45.0, 90.0, 127.5, 180.0, -60.0, 271.0}) {
    // Rotated about the box centre: same centre, same size.
    const Points pts = rectangle(c, yaw);
    const Node n = makeNode(pts, all(pts, 0));
    EXPECT_NEAR(n.size.x(), ref.size.x(), 1e-3) << yaw;
    EXPECT_NEAR(n.size.y(), ref.size.y(), 1e-3) << yaw;
    EXPECT_NEAR(n.size.z(), ref.size.z(), 1e-5) << yaw;
    EXPECT_GE(n.size.x(), n.size.y());
    EXPECT_NEAR((n.center.cast<double>() - c).norm(), 0.0, 1e-3) << yaw;
    // Rotated about the sensor (the same object seen from another heading): the centre turns with it.
    const Mat4d T = test::makeT(yaw, 0, 0, 0);
    const Points moved = test::transformPoints(T, rectangle(c, 0.0));
    const Node m = makeNode(moved, all(moved, 0));
    EXPECT_NEAR(m.size.x(), ref.size.x(), 1e-3) << yaw;
    EXPECT_NEAR(m.size.y(), ref.size.y(), 1e-3) << yaw;
    EXPECT_NEAR((m.center.cast<double>() - test::apply(T, c)).norm(), 0.0, 1e-3) << yaw;
  }
}

TEST(Graph, MakeNodeLengthAtLeastWidth) {
  // A rectangle elongated along y: length is still the larger horizontal extent.
  Points pts;
  for (int i = 0; i <= 5; ++i)
    for (int j = 0; j <= 30; ++j) pts.emplace_back(3.0f + 0.1f * i, 1.0f + 0.1f * j, 0.0f);
  const Node n = makeNode(pts, all(pts, 2));
  EXPECT_NEAR(n.size.x(), 3.0, 1e-4);
  EXPECT_NEAR(n.size.y(), 0.5, 1e-4);
  EXPECT_NEAR(n.size.z(), 0.0, 1e-6);
  EXPECT_NEAR(n.center.x(), 3.25, 1e-4);
  EXPECT_NEAR(n.center.y(), 2.5, 1e-4);
}

TEST(Graph, MakeNodeUsesOnlyClusterPoints) {
  Points pts = rectangle({5, 5, 0}, 0.0);
  const std::size_t n_rect = pts.size();
  pts.emplace_back(100.0f, 100.0f, 50.0f);  // not in the cluster
  Cluster c = all(pts, 0);
  c.points.resize(n_rect);
  const Node n = makeNode(pts, c);
  EXPECT_NEAR(n.size.x(), 4.0, 1e-4);
  EXPECT_NEAR(n.center.x(), 5.0, 1e-4);
}

TEST(Graph, AdjacencyDiagonalAndDmax) {
  std::vector<Node> nodes(4);
  nodes[0].center = Vec3f(0, 0, 0);
  nodes[1].center = Vec3f(30, 0, 0);   // 30 from 0
  nodes[2].center = Vec3f(30, 45, 0);  // 45 from 1, 54.08 from 0
  nodes[3].center = Vec3f(-70, 0, 0);  // 70 from 0, 100 from 1
  const Eigen::MatrixXd A = adjacency(nodes, 50.0);
  Eigen::MatrixXd expected(4, 4);
  expected << 1, 1, 0, 0,  //
      1, 1, 1, 0,          //
      0, 1, 1, 0,          //
      0, 0, 0, 1;
  EXPECT_EQ(A, expected);
  const Eigen::MatrixXd B = adjacency(nodes, 60.0);
  expected(0, 2) = expected(2, 0) = 1;  // 54.08 < 60
  EXPECT_EQ(B, expected);
  EXPECT_EQ(adjacency({}, 60.0).size(), 0);
  EXPECT_EQ(adjacency(std::vector<Node>(1), 60.0), Eigen::MatrixXd::Identity(1, 1));
}

TEST(Graph, AdjacencyUses3dDistance) {
  std::vector<Node> nodes(2);
  nodes[1].center = Vec3f(40, 0, 40);  // 56.6 m in 3-D, 40 m horizontally
  EXPECT_EQ(adjacency(nodes, 50.0)(0, 1), 0.0);
  EXPECT_EQ(adjacency(nodes, 60.0)(0, 1), 1.0);
}

TEST(Graph, BuildNodesKeepsLargestClusters) {
  // Five poles with 5, 20, 3, 15 and 10 points.
  const int counts[5] = {5, 20, 3, 15, 10};
  Points pts;
  std::vector<Cluster> clusters;
  for (int k = 0; k < 5; ++k) {
    Cluster c;
    c.cls = k % 3;
    for (int i = 0; i < counts[k]; ++i) {
      c.points.push_back(static_cast<std::uint32_t>(pts.size()));
      pts.emplace_back(10.0f * k, 5.0f, 0.3f * i);
    }
    clusters.push_back(c);
  }
  GraphConfig cfg;
  cfg.max_nodes = 3;
  std::vector<int> kept;
  const auto nodes = buildNodes(pts, clusters, cfg, &kept);
  EXPECT_EQ(kept, (std::vector<int>{1, 3, 4}));
  ASSERT_EQ(nodes.size(), 3u);
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    EXPECT_NEAR(nodes[i].center.x(), 10.0 * kept[i], 1e-4);
    EXPECT_EQ(nodes[i].cls, clusters[kept[i]].cls);
  }
  // Under the limit: every cluster, in order.
  cfg.max_nodes = 5;
  const auto all_nodes = buildNodes(pts, clusters, cfg, &kept);
  EXPECT_EQ(kept, (std::vector<int>{0, 1, 2, 3, 4}));
  EXPECT_EQ(all_nodes.size(), 5u);
  // kept_clusters is optional.
  EXPECT_EQ(buildNodes(pts, clusters, cfg, nullptr).size(), 5u);
}

TEST(Graph, BuildNodesDropsFragments) {
  // A pole 2 m tall, a flat 0.3 m blob, and a car 4 m long but only 0.4 m high.
  Points pts;
  std::vector<Cluster> clusters(3);
  auto add = [&](int k, float x, float y, float z) {
    clusters[k].points.push_back(static_cast<std::uint32_t>(pts.size()));
    pts.emplace_back(x, y, z);
  };
  clusters[0].cls = 2;
  clusters[1].cls = 1;
  clusters[2].cls = 0;
  for (int i = 0; i <= 20; ++i) add(0, 5.0f, 3.0f, -1.5f + 0.1f * i);
  for (int i = 0; i <= 12; ++i) add(1, 8.0f + 0.025f * i, -2.0f, -1.0f + 0.01f * (i % 3));
  for (int i = 0; i <= 40; ++i) add(2, -10.0f + 0.1f * i, 4.0f + 0.02f * (i % 5), -1.2f + 0.01f * (i % 40));
  GraphConfig cfg;  // min_extent_m 0.5
  std::vector<int> kept;
  const auto nodes = buildNodes(pts, clusters, cfg, &kept);
  EXPECT_EQ(kept, (std::vector<int>{0, 2}));
  ASSERT_EQ(nodes.size(), 2u);
  EXPECT_NEAR(nodes[0].size.z(), 2.0, 1e-4);
  EXPECT_NEAR(nodes[1].size.x(), 4.0, 1e-4);
  // The fragment counts neither against max_nodes nor as a node.
  cfg.max_nodes = 3;
  EXPECT_EQ(buildNodes(pts, clusters, cfg, nullptr).size(), 2u);
  cfg.min_extent_m = 0;
  EXPECT_EQ(buildNodes(pts, clusters, cfg, &kept).size(), 3u);
  EXPECT_EQ(kept, (std::vector<int>{0, 1, 2}));
  EXPECT_TRUE(buildNodes(pts, {}, cfg, &kept).empty());
  EXPECT_TRUE(kept.empty());
}

}  // namespace
}  // namespace sglc
