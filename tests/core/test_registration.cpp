// Closed-form rigid fit, deterministic RANSAC, instance ICP and plane refinement.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "sglc/registration.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::makeT;

std::vector<Vec3d> randomPoints(int n, std::uint32_t seed, double half = 40.0, double zhalf = 2.0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-half, half), uz(-zhalf, zhalf);
  std::vector<Vec3d> pts;
  for (int i = 0; i < n; ++i) pts.emplace_back(u(rng), u(rng), uz(rng));
  return pts;
}

std::vector<Vec3d> transformed(const Mat4d& T, const std::vector<Vec3d>& pts) {
  std::vector<Vec3d> out;
  for (const auto& p : pts) out.push_back(test::apply(T, p));
  return out;
}

void expectProperRigid(const Mat4d& T) {
  const Mat3d R = T.topLeftCorner<3, 3>();
  EXPECT_NEAR((R.transpose() * R - Mat3d::Identity()).norm(), 0.0, 1e-9);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-9);
  EXPECT_EQ(T.row(3), Eigen::RowVector4d(0, 0, 0, 1));
}

TEST(FitRigid, RecoversKnownTransform) {
  const auto src = randomPoints(25, 1);
  for (const Mat4d& T : {makeT(0, 0, 0, 0), makeT(37.0, 5.0, -3.0, 0.5, 4.0, -2.0), makeT(179.0, -100.0, 20.0, 3.0),
                         makeT(-90.0, 0.1, 0.2, 0.3, 30.0, 60.0)}) {
    const Mat4d F = fitRigid(src, transformed(T, src));
    EXPECT_LT((F - T).cwiseAbs().maxCoeff(), 1e-9) << "\n" << F << "\nvs\n" << T;
    expectProperRigid(F);
  }
}

TEST(FitRigid, ThreePointsAndCoplanarNoReflection) {
  const Mat4d T = makeT(-123.0, 7.0, 8.0, -1.0);
  const std::vector<Vec3d> three{{0, 0, 0}, {4, 0, 0}, {0, 3, 0}};
  EXPECT_LT((fitRigid(three, transformed(T, three)) - T).cwiseAbs().maxCoeff(), 1e-9);
  // Coplanar points (z = 0): the cross-covariance has rank 2, where an unguarded Kabsch can return a reflection.
  std::vector<Vec3d> flat;
  for (int i = 0; i < 10; ++i) flat.emplace_back(i * 1.7 - 5, (i * i) % 7 - 3.0, 0.0);
  const Mat4d F = fitRigid(flat, transformed(T, flat));
  expectProperRigid(F);
  EXPECT_LT((F - T).cwiseAbs().maxCoeff(), 1e-9);
}

struct RansacData {
  std::vector<Vec3d> query, candidate;
  std::set<int> outliers;
};

// query[i] = T * candidate[i] for inliers; outliers get their query point pushed 5-20 m away.
RansacData ransacData(int n, double outlier_share, const Mat4d& T, std::uint32_t seed) {
  RansacData d;
  d.candidate = randomPoints(n, seed);
  d.query = transformed(T, d.candidate);
  std::mt19937 rng(seed + 1);
  std::vector<int> idx(n);
  std::iota(idx.begin(), idx.end(), 0);
  std::shuffle(idx.begin(), idx.end(), rng);
  const int n_out = static_cast<int>(std::round(outlier_share * n));
  std::uniform_real_distribution<double> dist(5.0, 20.0), ang(0, 2 * std::numbers::pi);
  for (int k = 0; k < n_out; ++k) {
    const int i = idx[k];
    const double a = ang(rng), r = dist(rng);
    d.query[i] += Vec3d(r * std::cos(a), r * std::sin(a), 0.0);
    d.outliers.insert(i);
  }
  return d;
}

void expectRansacRecovers(const RansacData& d, const Mat4d& T, const RansacConfig& cfg) {
  const RansacResult r = ransacRigid(d.query, d.candidate, cfg);
  ASSERT_TRUE(r.found);
  EXPECT_LT((r.T - T).cwiseAbs().maxCoeff(), 1e-9) << "\n" << r.T << "\nvs\n" << T;
  std::vector<int> expected;
  for (int i = 0; i < static_cast<int>(d.query.size()); ++i)
    if (!d.outliers.count(i)) expected.push_back(i);
  EXPECT_EQ(r.inliers, expected);
  EXPECT_NEAR(r.mean_residual, 0.0, 1e-9);
  // Same input, same answer, bit for bit.
  const RansacResult again = ransacRigid(d.query, d.candidate, cfg);
  EXPECT_EQ(again.found, r.found);
  EXPECT_TRUE((again.T.array() == r.T.array()).all());
  EXPECT_EQ(again.inliers, r.inliers);
  EXPECT_EQ(again.mean_residual, r.mean_residual);
}

TEST(Ransac, ExhaustiveWithOutliers) {
  const Mat4d T = makeT(23.0, 4.5, -2.0, 0.3, 1.0, -0.5);
  const auto d = ransacData(20, 0.3, T, 7);  // C(20,3) = 1140 triples <= 2000: all tried
  ASSERT_EQ(d.outliers.size(), 6u);
  expectRansacRecovers(d, T, RansacConfig{});
}

TEST(Ransac, SampledWithOutliers) {
  const Mat4d T = makeT(-140.0, -30.0, 12.0, -0.4);
  const auto d = ransacData(60, 0.3, T, 8);  // C(60,3) = 34220 triples > 500: seeded sampling
  ASSERT_EQ(d.outliers.size(), 18u);
  RansacConfig cfg;
  cfg.max_iterations = 500;
  expectRansacRecovers(d, T, cfg);
}

TEST(Ransac, NoiseTolerated) {
  const Mat4d T = makeT(10.0, 3.0, 1.0, 0.0);
  auto d = ransacData(30, 0.2, T, 9);
  std::mt19937 rng(1);
  std::normal_distribution<double> noise(0.0, 0.05);
  for (int i = 0; i < 30; ++i)
    if (!d.outliers.count(i)) d.query[i] += Vec3d(noise(rng), noise(rng), noise(rng));
  const RansacResult r = ransacRigid(d.query, d.candidate, RansacConfig{});
  ASSERT_TRUE(r.found);
  EXPECT_LT(test::translationError(r.T, T), 0.1);
  EXPECT_LT(test::rotationErrorDeg(r.T, T), 0.5);
  EXPECT_EQ(r.inliers.size(), 24u);
  EXPECT_GT(r.mean_residual, 0.0);
  EXPECT_LT(r.mean_residual, 0.2);
}

TEST(Ransac, DegenerateInputs) {
  // Collinear: every triple is degenerate.
  std::vector<Vec3d> line;
  for (int i = 0; i < 12; ++i) line.emplace_back(1.5 * i, 0.5 * i, 0.1 * i);
  const Mat4d T = makeT(30.0, 1.0, 2.0, 0.0);
  EXPECT_FALSE(ransacRigid(transformed(T, line), line, RansacConfig{}).found);
  // Fewer than 3 matches.
  const auto two = randomPoints(2, 3);
  EXPECT_FALSE(ransacRigid(transformed(T, two), two, RansacConfig{}).found);
  EXPECT_FALSE(ransacRigid({}, {}, RansacConfig{}).found);
  // Mismatched sizes.
  const auto five = randomPoints(5, 4);
  EXPECT_FALSE(ransacRigid(transformed(T, five), randomPoints(4, 4), RansacConfig{}).found);
  // Not enough agreeing matches for min_inliers.
  RansacConfig cfg;
  cfg.min_inliers = 6;
  EXPECT_FALSE(ransacRigid(transformed(T, five), five, cfg).found);
  cfg.min_inliers = 5;
  EXPECT_TRUE(ransacRigid(transformed(T, five), five, cfg).found);
}

// Irregular instances: random points inside boxes of different sizes at different places.
std::vector<Points> instanceClouds(std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  const Vec3f centres[] = {{8, 3, -0.5f}, {-6, 9, 0.5f}, {15, -7, 0}, {-12, -10, 1}, {3, -14, 0}};
  const Vec3f halves[] = {
      {2.0f, 0.9f, 0.7f}, {0.3f, 0.3f, 2.5f}, {1.0f, 1.0f, 1.0f}, {0.4f, 1.5f, 2.0f}, {2.5f, 0.5f, 1.2f}};
  std::vector<Points> out;
  for (int k = 0; k < 5; ++k) {
    Points p;
    for (int i = 0; i < 120; ++i)
      p.push_back(centres[k] + Vec3f(u(rng) * halves[k].x(), u(rng) * halves[k].y(), u(rng) * halves[k].z()));
    out.push_back(p);
  }
  return out;
}

TEST(Icp, AlignsInstancesFromIdentity) {
  const Mat4d T = makeT(2.0, 0.25, -0.15, 0.05);  // 0.3 m, 2 deg
  const auto query = instanceClouds(3);
  std::vector<Points> candidate;
  for (const auto& q : query) candidate.push_back(test::transformPoints(T.inverse(), q));
  std::vector<std::pair<InstanceView, InstanceView>> pairs;
  for (std::size_t k = 0; k < query.size(); ++k)
    pairs.push_back({{query[k].data(), static_cast<int>(query[k].size())},
                     {candidate[k].data(), static_cast<int>(candidate[k].size())}});
  const IcpResult r = icpInstances(pairs, Mat4d::Identity(), FineConfig{});
  EXPECT_LT(test::translationError(r.T, T), 1e-3) << r.T;
  EXPECT_LT(test::rotationErrorDeg(r.T, T), 0.01);
  EXPECT_GT(r.iterations, 0);
  EXPECT_GT(r.fitness, 0.99);
  EXPECT_LT(r.rmse, 1e-3);
  EXPECT_EQ(r.correspondences, static_cast<int>(r.pairs.size()));
  // The final pairs are (query point, candidate point) with query ~= T * candidate.
  for (const auto& [qp, cp] : r.pairs) EXPECT_LT((test::apply(T, cp) - qp).norm(), 1e-3);
}

TEST(Icp, OnlyMatchedInstancesPair) {
  // Query instance 0 is paired with candidate instance 1 (a different object 20 m away): nothing within the
  // gate, so no correspondences and the start pose is kept.
  const auto clouds = instanceClouds(4);
  std::vector<std::pair<InstanceView, InstanceView>> pairs{
      {{clouds[0].data(), static_cast<int>(clouds[0].size())}, {clouds[1].data(), static_cast<int>(clouds[1].size())}}};
  const Mat4d T0 = makeT(1.0, 0.1, 0.0, 0.0);
  const IcpResult r = icpInstances(pairs, T0, FineConfig{});
  EXPECT_EQ(r.correspondences, 0);
  EXPECT_EQ(r.fitness, 0.0);
  EXPECT_TRUE(r.T.isApprox(T0, 1e-12));
  EXPECT_TRUE(icpInstances({}, T0, FineConfig{}).T.isApprox(T0, 1e-12));
}

// A box room seen from the origin: floor (z = -1.7), walls at x = +-10 and y = 8, sampled as plane features
// every metre, normals facing the sensor.
std::vector<Plane> roomPlanes() {
  std::vector<Plane> planes;
  auto add = [&](Vec3f c, Vec3f n, Background cls) {
    Plane p;
    p.centroid = c;
    p.normal = n;
    p.cls = static_cast<std::uint8_t>(cls);
    planes.push_back(p);
  };
  for (float x = -9.5f; x <= 9.5f; x += 1.0f)
    for (float y = -7.5f; y <= 7.5f; y += 1.0f) add({x, y, -1.7f}, {0, 0, 1}, Background::kRoad);
  for (float z = -1.2f; z <= 4.0f; z += 1.0f) {
    for (float y = -7.5f; y <= 7.5f; y += 1.0f) {
      add({10.0f, y, z}, {-1, 0, 0}, Background::kBuilding);
      add({-10.0f, y, z}, {1, 0, 0}, Background::kBuilding);
    }
    for (float x = -9.5f; x <= 9.5f; x += 1.0f) add({x, 8.0f, z}, {0, -1, 0}, Background::kFence);
  }
  return planes;
}

std::vector<Plane> movedPlanes(const std::vector<Plane>& planes, const Mat4d& T) {
  std::vector<Plane> out = planes;
  const Eigen::Matrix3f R = T.topLeftCorner<3, 3>().cast<float>();
  for (auto& p : out) {
    p.centroid = test::apply(T, p.centroid);
    p.normal = (R * p.normal).normalized();
  }
  return out;
}

Plane buildingPlane(const Vec3f& centroid, const Vec3f& normal) {
  Plane p;
  p.centroid = centroid;
  p.normal = normal;
  p.cls = static_cast<std::uint8_t>(Background::kBuilding);
  return p;
}

// A straight corridor 60 m long: road and two facades along x, planes every metre. Nothing fixes x.
std::vector<Plane> corridorPlanes() {
  std::vector<Plane> planes;
  auto add = [&](Vec3f c, Vec3f n) { planes.push_back(buildingPlane(c, n)); };
  for (float x = -29.5f; x <= 29.5f; x += 1.0f) {
    for (float y = -7.5f; y <= 7.5f; y += 1.0f) add({x, y, -1.7f}, {0, 0, 1});
    for (float z = -1.2f; z <= 4.0f; z += 1.0f) {
      add({x, 8.0f, z}, {0, -1, 0});
      add({x, -8.0f, z}, {0, 1, 0});
    }
  }
  return planes;
}

TEST(RefinePlanes, BoxRoomConverges) {
  const Mat4d T = makeT(2.0, 0.25, -0.15, 0.05, 0.5, -0.3);
  const auto query = roomPlanes();
  const auto candidate = movedPlanes(query, T.inverse());
  const PlaneIndex index(query, 1.0);
  const RefineResult r = refinePlanes(query, index, candidate, {}, Mat4d::Identity(), RefineConfig{});
  EXPECT_LT(test::translationError(r.T, T), 1e-3) << r.T;
  EXPECT_LT(test::rotationErrorDeg(r.T, T), 0.01);
  EXPECT_GT(r.iterations, 0);
  EXPECT_LT(r.rmse, 1e-3);
  EXPECT_GT(r.fitness, 0.95);
  EXPECT_EQ(r.correspondences, static_cast<int>(std::lround(r.fitness * candidate.size())));
}

// Instance correspondences (query point, candidate point) around the sensor, consistent with T up to `bias`
// added to the query side.
std::vector<std::pair<Vec3f, Vec3f>> anchorPairs(const Mat4d& T, const Vec3d& bias) {
  std::vector<std::pair<Vec3f, Vec3f>> pairs;
  for (int k = 0; k < 60; ++k) {
    const Vec3f c(static_cast<float>(-12 + 0.4 * k), static_cast<float>(k % 2 ? 5.0 : -5.0),
                  static_cast<float>(-1.5 + 0.05 * (k % 40)));
    pairs.emplace_back((test::apply(T, c).cast<double>() + bias).cast<float>(), c);
  }
  return pairs;
}

TEST(RefinePlanes, BiasedAnchorDoesNotMoveAConstrainedPose) {
  // The room's planes fix all six directions: instance pairs biased by 5 cm (views of the same trunks from
  // other sides) must not pull the pose.
  const Mat4d T = makeT(2.0, 0.25, -0.15, 0.05, 0.5, -0.3);
  const auto query = roomPlanes();
  const auto candidate = movedPlanes(query, T.inverse());
  const PlaneIndex index(query, 1.0);
  const auto anchor = anchorPairs(T, Vec3d(0.05, 0.0, 0.0));
  const RefineResult r = refinePlanes(query, index, candidate, anchor, Mat4d::Identity(), RefineConfig{});
  EXPECT_LT(test::translationError(r.T, T), 2e-3) << r.T;
  EXPECT_LT(test::rotationErrorDeg(r.T, T), 0.01);
  // An anchor acting in all of yaw, x and y (min_information above any eigenvalue) is pulled by the bias.
  RefineConfig everywhere;
  everywhere.min_information = 1e12;
  const RefineResult pulled = refinePlanes(query, index, candidate, anchor, Mat4d::Identity(), everywhere);
  EXPECT_GT(test::translationError(pulled.T, T), 0.01) << pulled.T;
}

TEST(RefinePlanes, CorridorTakesTheFreeDirectionFromTheAnchor) {
  // A straight corridor: road and two facades along x. Planes say nothing about x; the anchor does.
  const std::vector<Plane> query = corridorPlanes();
  const Mat4d T = makeT(1.0, 1.3, 0.2, 0.0);
  const auto candidate = movedPlanes(query, T.inverse());
  const PlaneIndex index(query, 1.0);
  const Mat4d T0 = makeT(1.0, 1.0, 0.2, 0.0);  // 0.3 m short along the corridor
  const RefineResult r = refinePlanes(query, index, candidate, anchorPairs(T, Vec3d::Zero()), T0, RefineConfig{});
  EXPECT_LT(test::translationError(r.T, T), 5e-3) << r.T;
  EXPECT_LT(test::rotationErrorDeg(r.T, T), 0.02);
  // Without the anchor x stays where it started.
  const RefineResult free = refinePlanes(query, index, candidate, {}, T0, RefineConfig{});
  EXPECT_GT(std::abs(free.T(0, 3) - T(0, 3)), 0.2) << free.T;
}

// A narrow road (2 m of ground across) between two facades seen only at one height: roll about the road's
// axis has little plane information (below min_information at the 10 m lever), yet the anchor must not set it.
// Instance pairs tilt (a car's points are sampled differently from two viewpoints); the ground does not.
TEST(RefinePlanes, AnchorDoesNotTiltAWeaklyConstrainedRoll) {
  std::vector<Plane> query;
  auto add = [&](Vec3f c, Vec3f n) { query.push_back(buildingPlane(c, n)); };
  for (float x = -29.5f; x <= 29.5f; x += 1.0f) {
    for (float y : {-0.5f, 0.5f}) add({x, y, -1.7f}, {0, 0, 1});
    add({x, 8.0f, 1.0f}, {0, -1, 0});
    add({x, -8.0f, 1.0f}, {0, 1, 0});
  }
  const Mat4d T = makeT(1.0, 1.3, 0.2, 0.0);
  const auto candidate = movedPlanes(query, T.inverse());
  const PlaneIndex index(query, 1.0);
  const Mat4d tilt = makeT(0.0, 0.0, 0.0, 0.0, 0.0, 0.5);  // the pairs agree with a pose rolled by 0.5 deg
  const auto tilted = anchorPairs(tilt * T, Vec3d::Zero());
  const Mat4d T0 = makeT(1.0, 1.0, 0.2, 0.0);  // 0.3 m short along the road: the anchor's job
  const RefineResult r = refinePlanes(query, index, candidate, tilted, T0, RefineConfig{});
  EXPECT_LT(test::rotationErrorDeg(r.T, T), 0.05) << r.T;
  EXPECT_LT(std::abs(r.T(0, 3) - T(0, 3)), 0.05) << r.T;  // x still comes from the anchor
  // An anchor acting in all of yaw, x and y is pulled off by the tilted pairs (through yaw): the check above can
  // tell a pulled pose from a held one.
  RefineConfig everywhere;
  everywhere.min_information = 1e12;
  const RefineResult pulled = refinePlanes(query, index, candidate, tilted, T0, everywhere);
  EXPECT_GT(test::rotationErrorDeg(pulled.T, T), 0.1) << pulled.T;
}

Mat4d rightPerturbed(const Mat4d& T, const Eigen::Matrix<double, 6, 1>& xi) {
  Mat4d E = Mat4d::Identity();
  const Vec3d phi = xi.tail<3>();
  if (phi.norm() > 0) E.topLeftCorner<3, 3>() = Eigen::AngleAxisd(phi.norm(), phi.normalized()).toRotationMatrix();
  E.topRightCorner<3, 1>() = xi.head<3>();
  return T * E;
}

// The information is the curvature of the whitened residuals for a right perturbation, translation first:
// moving the converged pose by xi raises sum(r^2) / sigma^2 by xi' I xi.
TEST(RefinePlanes, InformationIsTheResidualCurvature) {
  const Mat4d T = makeT(35.0, 4.0, -2.5, 0.3, 1.0, -0.5);
  const auto query = roomPlanes();
  const auto candidate = movedPlanes(query, T.inverse());
  const PlaneIndex index(query, 1.0);
  const RefineResult r = refinePlanes(query, index, candidate, {}, makeT(0.5, 0.1, -0.1, 0.02) * T, RefineConfig{});
  ASSERT_LT(test::translationError(r.T, T), 1e-3);
  const Mat6d& I = r.information;
  EXPECT_LT((I - I.transpose()).norm(), 1e-6 * I.norm());
  const double sigma = 0.01;  // exact planes: the 1 cm floor
  RefineConfig look;
  look.max_iterations = 0;  // evaluate only
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  for (const Vec6& xi : {(Vec6() << 0.01, 0, 0, 0, 0, 0).finished(), (Vec6() << 0, 0, 0.01, 0, 0, 0).finished(),
                         (Vec6() << 0, 0, 0, 0, 0, 0.001).finished(), (Vec6() << 0, 0, 0, 0.001, 0, 0).finished(),
                         (Vec6() << 0.005, -0.004, 0.003, 0.0005, -0.0003, 0.0008).finished()}) {
    const RefineResult at = refinePlanes(query, index, candidate, {}, rightPerturbed(r.T, xi), look);
    const double cost = at.rmse * at.rmse * at.correspondences / (sigma * sigma);
    EXPECT_NEAR(cost, xi.dot(I * xi), 0.05 * cost) << xi.transpose();
  }
}

TEST(RefinePlanes, InformationIsSmallAlongACorridor) {
  const std::vector<Plane> query = corridorPlanes();
  const Mat4d T = makeT(0.0, 0.0, 0.3, 0.0);
  const PlaneIndex index(query, 1.0);
  const RefineResult r =
      refinePlanes(query, index, movedPlanes(query, T.inverse()), {}, Mat4d::Identity(), RefineConfig{});
  const Mat6d& I = r.information;
  EXPECT_LT(I(0, 0), 1e-6 * I(1, 1));  // along the corridor: nothing
  EXPECT_GT(I(1, 1), 1e6);             // across it and vertically: plenty (1 cm sigma, hundreds of planes)
  EXPECT_GT(I(2, 2), 1e6);
}

TEST(RefinePlanes, TooFewPlanesKeepsStart) {
  const auto query = roomPlanes();
  const PlaneIndex index(query, 1.0);
  const std::vector<Plane> few(query.begin(), query.begin() + 4);  // fewer than 6 correspondences
  const Mat4d T0 = makeT(1.0, 0.2, 0.0, 0.0);
  const RefineResult r = refinePlanes(query, index, few, {}, T0, RefineConfig{});
  EXPECT_EQ(r.iterations, 0);
  EXPECT_TRUE(r.T.isApprox(T0, 1e-12));
  const RefineResult none = refinePlanes(query, index, {}, {}, T0, RefineConfig{});
  EXPECT_EQ(none.fitness, 0.0);
  EXPECT_TRUE(none.T.allFinite());
}

}  // namespace
}  // namespace sglc
