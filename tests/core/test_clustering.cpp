// Instance clustering over range-adaptive polar voxels.
#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>
#include <set>

#include "sglc/clustering.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::makePole;

struct Input {
  Points points;
  std::vector<std::int8_t> cls;
  void add(const Points& pts, int c) {
    for (const auto& p : pts) {
      points.push_back(p);
      cls.push_back(static_cast<std::int8_t>(c));
    }
  }
};

// Clusters as sets of point indices (order-free), for comparing partitions.
std::set<std::vector<std::uint32_t>> partition(const std::vector<Cluster>& clusters) {
  std::set<std::vector<std::uint32_t>> out;
  for (const auto& c : clusters) {
    auto pts = c.points;
    std::sort(pts.begin(), pts.end());
    out.insert(pts);
  }
  return out;
}

TEST(Clustering, EmptyInput) {
  EXPECT_TRUE(clusterInstances({}, {}, ClusterConfig{}).empty());
  // Points that all belong to no class.
  Input in;
  in.add(makePole(10, 0, -1.5, 2.0), -1);
  EXPECT_TRUE(clusterInstances(in.points, in.cls, ClusterConfig{}).empty());
}

TEST(Clustering, TwoSeparatedPoles) {
  Input in;
  const Points a = makePole(10, 0, -1.5, 2.0);
  const Points b = makePole(8, 9, -1.5, 2.5);
  in.add(a, 2);
  in.add(b, 2);
  const auto clusters = clusterInstances(in.points, in.cls, ClusterConfig{});
  ASSERT_EQ(clusters.size(), 2u);
  // First cluster is pole a (indices 0..|a|-1), second pole b.
  std::vector<std::uint32_t> ia(a.size()), ib(b.size());
  std::iota(ia.begin(), ia.end(), 0u);
  std::iota(ib.begin(), ib.end(), static_cast<std::uint32_t>(a.size()));
  EXPECT_EQ(clusters[0].points, ia);
  EXPECT_EQ(clusters[1].points, ib);
  EXPECT_EQ(clusters[0].cls, 2);
  EXPECT_EQ(clusters[1].cls, 2);
}

TEST(Clustering, ClassesNeverJoin) {
  // One physical pole whose points alternate between two classes.
  const Points pole = makePole(12, -3, -1.5, 2.5);
  Input in;
  for (std::size_t i = 0; i < pole.size(); ++i) in.add({pole[i]}, static_cast<int>(i % 2));
  const auto clusters = clusterInstances(in.points, in.cls, ClusterConfig{});
  ASSERT_EQ(clusters.size(), 2u);
  for (const auto& c : clusters) {
    EXPECT_EQ(c.points.size(), pole.size() / 2);
    for (auto i : c.points) EXPECT_EQ(in.cls[i], c.cls) << "point " << i;
  }
  EXPECT_EQ(clusters[0].cls, 0);
  EXPECT_EQ(clusters[1].cls, 1);
}

TEST(Clustering, SmallClustersDropped) {
  ClusterConfig cfg;
  cfg.min_points = 10;
  Input in;
  // 9 points: dropped. 10 points: kept (the threshold is "fewer than min_points are dropped").
  Points nine, ten;
  for (int k = 0; k < 9; ++k) nine.emplace_back(10.0f, 0.0f, -1.0f + 0.1f * k);
  for (int k = 0; k < 10; ++k) ten.emplace_back(0.0f, 15.0f, -1.0f + 0.1f * k);
  in.add(nine, 0);
  in.add(ten, 0);
  const auto clusters = clusterInstances(in.points, in.cls, cfg);
  ASSERT_EQ(clusters.size(), 1u);
  EXPECT_EQ(clusters[0].points.size(), 10u);
  EXPECT_EQ(clusters[0].points.front(), 9u);
  cfg.min_points = 11;
  EXPECT_TRUE(clusterInstances(in.points, in.cls, cfg).empty());
  cfg.min_points = 1;
  EXPECT_EQ(clusterInstances(in.points, in.cls, cfg).size(), 2u);
}

TEST(Clustering, PointsBeyondMaxRangeIgnored) {
  ClusterConfig cfg;
  cfg.max_range_m = 30;
  Input in;
  in.add(makePole(20, 0, -1, 2), 0);
  in.add(makePole(0, 40, -1, 2), 0);  // beyond 30 m
  const auto clusters = clusterInstances(in.points, in.cls, cfg);
  ASSERT_EQ(clusters.size(), 1u);
  EXPECT_EQ(clusters[0].points.front(), 0u);
}

// The azimuth of a point on the -x axis jumps from +pi to -pi: a pole straddling it must stay one cluster.
TEST(Clustering, AzimuthWrapAroundStaysOneCluster) {
  for (double azimuth_deg : {2.0, 1.0, 3.0, 5.0}) {
    ClusterConfig cfg;
    cfg.azimuth_deg = azimuth_deg;
    for (double range : {6.0, 15.0, 30.0}) {
      // A pole of radius 0.2 m centred on the -x axis: 16 points per ring (0.08 m apart, under 1 degree of
      // azimuth at 6 m), none exactly on y = 0, half at y > 0 (azimuth near +pi), half at y < 0 (near -pi).
      const double phase = std::numbers::pi / 16;
      Input in;
      in.add(makePole(-range, 0.0, -1.5, 2.0, 0.2, 16, 0.1, phase), 2);
      const auto clusters = clusterInstances(in.points, in.cls, cfg);
      EXPECT_EQ(clusters.size(), 1u) << "azimuth_deg " << azimuth_deg << ", pole at x = " << -range;
      // Control: the same pole on the +x axis (no wrap-around) is one cluster.
      Input ctl;
      ctl.add(makePole(range, 0.0, -1.5, 2.0, 0.2, 16, 0.1, phase), 2);
      EXPECT_EQ(clusterInstances(ctl.points, ctl.cls, cfg).size(), 1u);
    }
  }
}

TEST(Clustering, StableOrderByClassThenFirstPoint) {
  Input in;
  in.add(makePole(10, 10, -1.5, 2.0), 1);  // first points, class 1
  in.add(makePole(-10, 8, -1.5, 2.0), 0);  // class 0, later first index
  in.add(makePole(5, -12, -1.5, 2.0), 1);
  in.add(makePole(20, 3, -1.5, 2.0), 0);
  const auto a = clusterInstances(in.points, in.cls, ClusterConfig{});
  const auto b = clusterInstances(in.points, in.cls, ClusterConfig{});
  ASSERT_EQ(a.size(), 4u);
  ASSERT_EQ(b.size(), 4u);
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].cls, b[k].cls);
    EXPECT_EQ(a[k].points, b[k].points);
    EXPECT_TRUE(std::is_sorted(a[k].points.begin(), a[k].points.end()));
  }
  const std::size_t n = makePole(0, 0, -1.5, 2.0).size();
  EXPECT_EQ(a[0].cls, 0);
  EXPECT_EQ(a[0].points.front(), n);  // the class-0 pole at (-10, 8)
  EXPECT_EQ(a[1].cls, 0);
  EXPECT_EQ(a[1].points.front(), 3 * n);
  EXPECT_EQ(a[2].cls, 1);
  EXPECT_EQ(a[2].points.front(), 0u);
  EXPECT_EQ(a[3].cls, 1);
  EXPECT_EQ(a[3].points.front(), 2 * n);
}

TEST(Clustering, PartitionIndependentOfPointOrder) {
  Input in;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-35.0, 35.0);
  for (int k = 0; k < 25; ++k) in.add(makePole(u(rng), u(rng), -1.5, 1.0 + 0.1 * k), k % 3);
  const auto base = clusterInstances(in.points, in.cls, ClusterConfig{});
  ASSERT_GE(base.size(), 10u);
  std::vector<std::uint32_t> perm(in.points.size());
  std::iota(perm.begin(), perm.end(), 0u);
  std::shuffle(perm.begin(), perm.end(), rng);
  Input sh;
  for (auto i : perm) sh.add({in.points[i]}, in.cls[i]);
  auto shuffled = clusterInstances(sh.points, sh.cls, ClusterConfig{});
  for (auto& c : shuffled)
    for (auto& i : c.points) i = perm[i];  // back to the original indices
  EXPECT_EQ(partition(shuffled), partition(base));
}

}  // namespace
}  // namespace sglc
