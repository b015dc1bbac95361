// The plane lookup against a brute-force search: same answer for every point, radius and normal gate.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "sglc/fingerprint.hpp"
#include "sglc/plane_index.hpp"

namespace sglc {
namespace {

std::vector<Plane> randomPlanes(int n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-20.f, 20.f), uz(-2.f, 4.f), un(-1.f, 1.f);
  std::vector<Plane> planes;
  for (int i = 0; i < n; ++i) {
    Plane p;
    // Centroids on a 1 cm grid, as stored, so that some fall exactly on cell faces.
    p.centroid = Vec3f(std::round(u(rng) * 100.f) / 100.f, std::round(u(rng) * 100.f) / 100.f,
                       std::round(uz(rng) * 100.f) / 100.f);
    p.normal = Vec3f(un(rng), un(rng), un(rng)).normalized();
    planes.push_back(p);
  }
  // Two planes at one place: the lower index wins the tie.
  planes.push_back(planes[3]);
  return planes;
}

int bruteNearest(const std::vector<Plane>& planes, const Vec3f& p, const Vec3f& n, double max_dist, double min_cos) {
  float best = static_cast<float>(max_dist * max_dist);
  int arg = -1;
  for (std::size_t i = 0; i < planes.size(); ++i) {
    const float d2 = (planes[i].centroid - p).squaredNorm();
    if (d2 < best && std::abs(planes[i].normal.dot(n)) >= static_cast<float>(min_cos)) {
      best = d2;
      arg = static_cast<int>(i);
    }
  }
  return arg;
}

TEST(PlaneIndex, NearestRespectsDistanceAndNormal) {
  std::vector<Plane> planes(3);
  planes[0].centroid = Vec3f(0.2f, 0.2f, 0.2f);
  planes[0].normal = Vec3f(0, 0, 1);
  planes[1].centroid = Vec3f(0.4f, 0.2f, 0.2f);  // same cell as plane 0
  planes[1].normal = Vec3f(1, 0, 0);
  planes[2].centroid = Vec3f(3.0f, 0.0f, 0.0f);
  planes[2].normal = Vec3f(0, 0, -1);
  const PlaneIndex index(planes, 1.0);
  EXPECT_EQ(index.nearest(planes, Vec3f(0.45f, 0.2f, 0.2f), Vec3f(0, 0, 1), 1.0, 0.9), 0);  // 1 is closer, wrong n
  EXPECT_EQ(index.nearest(planes, Vec3f(0.45f, 0.2f, 0.2f), Vec3f(1, 0, 0), 1.0, 0.9), 1);
  EXPECT_EQ(index.nearest(planes, Vec3f(0.45f, 0.2f, 0.2f), Vec3f(-1, 0, 0), 1.0, 0.9), 1);  // |cos|
  EXPECT_EQ(index.nearest(planes, Vec3f(2.5f, 0.0f, 0.0f), Vec3f(0, 0, 1), 1.0, 0.9), 2);    // other voxel
  EXPECT_EQ(index.nearest(planes, Vec3f(1.5f, 0.0f, 0.0f), Vec3f(0, 0, 1), 1.0, 0.9), -1);   // none within 1 m
  EXPECT_EQ(PlaneIndex().nearest({}, Vec3f::Zero(), Vec3f::UnitZ(), 1.0, 0.9), -1);
}

TEST(PlaneIndex, AgreesWithBruteForceForEveryRadius) {
  const auto planes = randomPlanes(1500, 7);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-23.f, 23.f), uz(-5.f, 7.f), un(-1.f, 1.f), jitter(-1.2f, 1.2f);
  for (const double radius : {0.3, 1.0, 2.5}) {
    SCOPED_TRACE(radius);
    const PlaneIndex index(planes, radius);
    int found = 0, checked = 0;
    for (int k = 0; k < 20000; ++k) {
      // Half the points near a plane (most lookups in refinement hit one), half anywhere, some outside the bounds.
      const Vec3f p = k % 2 ? planes[static_cast<std::size_t>(k) % planes.size()].centroid +
                                  Vec3f(jitter(rng), jitter(rng), jitter(rng)) * static_cast<float>(radius)
                            : Vec3f(u(rng), u(rng), uz(rng));
      const Vec3f n = Vec3f(un(rng), un(rng), un(rng)).normalized();
      for (const double max_dist : {radius, radius * 0.5}) {
        for (const double min_cos : {0.0, 0.8}) {
          const int got = index.nearest(planes, p, n, max_dist, min_cos);
          ASSERT_EQ(got, bruteNearest(planes, p, n, max_dist, min_cos)) << p.transpose();
          found += got >= 0;
          ++checked;
        }
      }
    }
    EXPECT_GT(found, checked / 20);  // the check covered hits, not only misses
    EXPECT_EQ(index.nearest(planes, planes[3].centroid, planes[3].normal, radius, 0.0), 3);
  }
}

TEST(PlaneIndex, RejectsBadRadiiAndPoints) {
  const auto planes = randomPlanes(50, 3);
  for (const double bad :
       {0.0, -1.0, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()})
    EXPECT_THROW(PlaneIndex(planes, bad), InputError) << bad;
  const PlaneIndex index(planes, 1.0);
  // A lookup wider than the index was built for would miss planes: refused, not answered wrongly.
  EXPECT_THROW(index.nearest(planes, planes[0].centroid, planes[0].normal, 1.5, 0.0), InputError);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(index.nearest(planes, Vec3f(nan, 0, 0), Vec3f::UnitZ(), 1.0, 0.0), -1);
  EXPECT_EQ(index.nearest(planes, Vec3f(inf, 0, 0), Vec3f::UnitZ(), 1.0, 0.0), -1);
  EXPECT_EQ(index.nearest(planes, Vec3f(3e9f, -3e9f, 0), Vec3f::UnitZ(), 1.0, 0.0), -1);
  EXPECT_THROW(index.nearest(planes, planes[0].centroid, planes[0].normal, -0.5, 0.0), InputError);
  // Centroids the cells cannot hold: refused when the index is built, not missed later.
  auto far = planes;
  far[1].centroid.x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(PlaneIndex(far, 1.0), InputError);
  far = planes;
  far[1].centroid.x() = 300.0f;
  EXPECT_THROW(PlaneIndex(far, 1e-7), InputError);
  EXPECT_NO_THROW(PlaneIndex(far, 1e-3));
  const PlaneIndex empty({}, 1.0);
  EXPECT_EQ(empty.nearest({}, Vec3f::Zero(), Vec3f::UnitZ(), 1.0, 0.0), -1);
  // Planes other than those it was built from (here one fewer) would be read out of bounds: refused.
  auto fewer = planes;
  fewer.pop_back();
  EXPECT_THROW(index.nearest(fewer, planes[0].centroid, planes[0].normal, 1.0, 0.0), InputError);
  EXPECT_THROW(empty.nearest(planes, planes[0].centroid, planes[0].normal, 1.0, 0.0), InputError);
}

// A radius float cannot hold: a point just within reach of a plane at the bounds' edge is still found.
TEST(PlaneIndex, FindsPlanesAtTheEdgeOfItsBounds) {
  std::vector<Plane> planes(1);
  planes[0].centroid = Vec3f(-2.05f, 0, 0);
  planes[0].normal = Vec3f::UnitX();
  const PlaneIndex index(planes, 1.05);
  for (float x = -1.0f - 4e-7f; x < -0.999f; x = std::nextafter(x, 0.0f)) {
    const Vec3f p(x, 0, 0);
    EXPECT_EQ(index.nearest(planes, p, Vec3f::UnitX(), 1.05, 0.0), bruteNearest(planes, p, Vec3f::UnitX(), 1.05, 0.0))
        << x;
    if (x > -0.99999f) break;
  }
}

TEST(PlaneIndex, KeptWithTheFingerprintPerRadius) {
  Fingerprint fp;
  fp.planes = randomPlanes(40, 5);
  const auto a = planeIndexOf(fp, 1.0);
  EXPECT_EQ(planeIndexOf(fp, 1.0), a);  // built once
  const auto b = planeIndexOf(fp, 2.0);
  EXPECT_DOUBLE_EQ(b->radius(), 2.0);  // another radius is another lookup, never the kept one
  EXPECT_DOUBLE_EQ(planeIndexOf(fp, 1.0)->radius(), 1.0);
  const Fingerprint copy = fp;  // a copy may have its planes changed: it builds its own
  EXPECT_NE(planeIndexOf(copy, 1.0), planeIndexOf(fp, 1.0));
  // A moved-from fingerprint keeps its lookup but not its planes: asking it is refused, not read past the end.
  Fingerprint moved = fp;
  ASSERT_TRUE(planeIndexOf(moved, 1.0));
  const Fingerprint taken = std::move(moved);
  EXPECT_EQ(taken.planes.size(), fp.planes.size());
  EXPECT_THROW(planeIndexOf(moved, 1.0)->nearest(moved.planes, Vec3f::Zero(), Vec3f::UnitZ(), 1.0, 0.0),  // NOLINT
               InputError);
}

}  // namespace
}  // namespace sglc
