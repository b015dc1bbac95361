// Trajectories and ground truth lists.
#include "sim/ground_truth.hpp"
#include "sim_test_util.hpp"

namespace sglc::sim::test {
namespace {

Mat4d poseAt(double x, double y, double yaw_deg) {
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(yaw_deg * std::numbers::pi / 180.0, Vec3d::UnitZ()).toRotationMatrix();
  T.topRightCorner<3, 1>() = Vec3d(x, y, 0.0);
  return T;
}

TEST(Trajectory, KittiPosesBecomeLidarPoses) {
  // Tr: velodyne -> cam0, as in KITTI (x forward -> z forward, y left -> -x, z up -> -y), with an offset.
  Mat4d Tr = Mat4d::Zero();
  Tr(0, 1) = -1;
  Tr(1, 2) = -1;
  Tr(2, 0) = 1;
  Tr(3, 3) = 1;
  Tr.topRightCorner<3, 1>() = Vec3d(-0.01, -0.05, -0.3);
  // The camera moves 10 m forward (its z axis) and turns 90 deg left (about its -y axis).
  Mat4d P1 = Mat4d::Identity();
  P1.topLeftCorner<3, 3>() = Eigen::AngleAxisd(std::numbers::pi / 2, -Vec3d::UnitY()).toRotationMatrix();
  P1.topRightCorner<3, 1>() = Vec3d(0, 0, 10);
  const auto t = kittiTrajectory({Mat4d::Identity(), P1}, Tr, "synthetic");
  ASSERT_EQ(t.poses.size(), 2u);
  EXPECT_LT((t.poses[0] - Mat4d::Identity()).norm(), 1e-12);
  EXPECT_LT((t.poses[1] - Tr.inverse() * P1 * Tr).norm(), 1e-12);
  // In the LiDAR frame: about 10 m along x (forward; the lever arm of Tr adds 0.29 m), turned +90 deg
  // about z (left).
  EXPECT_NEAR(t.poses[1](0, 3), 10.29, 1e-9);
  EXPECT_NEAR(t.poses[1](1, 3), -0.31, 1e-9);
  EXPECT_NEAR(std::atan2(t.poses[1](1, 0), t.poses[1](0, 0)), std::numbers::pi / 2, 1e-9);
  Mat4d bad = Tr;
  bad(0, 0) = 3;
  EXPECT_THROW(kittiTrajectory({Mat4d::Identity()}, bad), InputError);
}

TEST(Trajectory, LoopRouteRevisitsBothWays) {
  const auto& t = loopTrajectory();
  ASSERT_GT(t.poses.size(), 1500u);
  EXPECT_LT((t.poses[0] - Mat4d::Identity()).norm(), 1e-9);
  for (std::size_t k = 1; k < t.poses.size(); ++k) {
    const double step = translationError(t.poses[k], t.poses[k - 1]);
    ASSERT_GT(step, 0.3) << k;
    ASSERT_LT(step, 1.0) << k;
  }
  std::vector<int> source(t.poses.size());
  for (std::size_t k = 0; k < source.size(); ++k) source[k] = static_cast<int>(k);
  const auto rows = loopPoses(t.poses, source, 3.0, 50);
  int same = 0, reverse = 0;
  for (const auto& r : rows) {
    const double d = headingDifferenceDeg(t.poses[r.first], t.poses[r.second]);
    same += d < 30;
    reverse += d > 150;
  }
  EXPECT_GT(same, 500);
  EXPECT_GT(reverse, 500);
}

TEST(Trajectory, Kitti08HasReverseRevisits) {
  SGLC_REQUIRE_KITTI("08");
  const auto& t = kittiSequence("08");
  ASSERT_EQ(t.poses.size(), 4071u);
  std::vector<int> source(t.poses.size());
  for (std::size_t k = 0; k < source.size(); ++k) source[k] = static_cast<int>(k);
  PairListConfig cfg;
  const auto pairs = distancePairs(t.poses, source, cfg);
  int positives = 0, reverse = 0;
  for (const auto& p : pairs)
    if (p.loop) {
      ++positives;
      reverse += headingDifferenceDeg(t.poses[p.query], t.poses[p.database]) > 150;
    }
  // KITTI 08 closes its loops almost only in the opposite direction.
  EXPECT_GT(positives, 1000);
  EXPECT_GT(reverse, positives * 0.8);
}

TEST(GroundTruth, DistancePairsFollowTheProtocol) {
  // A straight road driven out and back: frames 0..99 east, 100..199 west along the same line.
  std::vector<Mat4d> poses;
  std::vector<int> source;
  for (int k = 0; k < 200; ++k) {
    poses.push_back(k < 100 ? poseAt(k, 0, 0) : poseAt(199 - k, 1.0, 180));
    source.push_back(k * 2);
  }
  PairListConfig cfg;
  cfg.min_gap = 50;
  cfg.seed = 3;
  const auto pairs = distancePairs(poses, source, cfg);
  int pos = 0, neg = 0;
  for (const auto& p : pairs) {
    ASSERT_GT(p.query, p.database);
    const double d =
        std::hypot(poses[p.query](0, 3) - poses[p.database](0, 3), poses[p.query](1, 3) - poses[p.database](1, 3));
    if (p.loop) {
      ++pos;
      EXPECT_LT(d, 3.0);
      EXPECT_GT(source[p.query] - source[p.database], 50);
    } else {
      ++neg;
      EXPECT_GT(d, 20.0);
    }
  }
  EXPECT_GT(pos, 100);
  EXPECT_EQ(neg, 10 * pos);
  EXPECT_TRUE(std::is_sorted(pairs.begin(), pairs.end(), [](const LabelledPair& a, const LabelledPair& b) {
    return a.query != b.query ? a.query < b.query : a.database < b.database;
  }));
  // Same seed, same list; another seed, other negatives.
  const auto again = distancePairs(poses, source, cfg);
  ASSERT_EQ(again.size(), pairs.size());
  EXPECT_TRUE(std::equal(pairs.begin(), pairs.end(), again.begin(), [](const auto& a, const auto& b) {
    return a.query == b.query && a.database == b.database && a.loop == b.loop;
  }));
  cfg.seed = 4;
  const auto other = distancePairs(poses, source, cfg);
  EXPECT_FALSE(std::equal(pairs.begin(), pairs.end(), other.begin(),
                          [](const auto& a, const auto& b) { return a.query == b.query && a.database == b.database; }));
}

TEST(GroundTruth, LoopPosesMapEarlierIntoLater) {
  const std::vector<Mat4d> poses = {poseAt(0, 0, 0), poseAt(50, 0, 90), poseAt(1.0, 2.0, 180)};
  const std::vector<int> source = {0, 40, 100};
  const auto rows = loopPoses(poses, source, 4.0, 50);
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].first, 0);
  EXPECT_EQ(rows[0].second, 2);
  // A point 5 m ahead of frame 0, seen from frame 2 (at (1, 2), facing back): 4 m behind it and 2 m to its
  // left, and p_2 = T * p_0.
  const Vec3d p0(5, 0, 0);
  const Vec3d world = (poses[0] * p0.homogeneous()).head<3>();
  const Vec3d p2 = (rows[0].T * p0.homogeneous()).head<3>();
  EXPECT_LT(((poses[2] * p2.homogeneous()).head<3>() - world).norm(), 1e-12);
  EXPECT_NEAR(p2.x(), -4.0, 1e-12);
  EXPECT_NEAR(p2.y(), 2.0, 1e-12);
}

TEST(GroundTruth, OdometryDriftsFromTheTruth) {
  const auto& t = loopTrajectory();
  std::vector<Mat4d> poses(t.poses.begin(), t.poses.begin() + 600);
  std::vector<int> source(poses.size());
  for (std::size_t k = 0; k < source.size(); ++k) source[k] = static_cast<int>(k);
  const auto exact = driftingOdometry(poses, source, OdometryNoise{}, 7);
  for (std::size_t k = 0; k < poses.size(); ++k) ASSERT_LT((exact[k] - poses[k]).norm(), 1e-9);
  const auto odo = driftingOdometry(poses, source, OdometryNoise{0.01, 0.005}, 7);
  EXPECT_LT((odo[0] - poses[0]).norm(), 1e-12);
  const double err_end = translationError(odo.back(), poses.back());
  EXPECT_GT(err_end, 0.01);
  EXPECT_LT(err_end, 0.05 * 500.0);  // 600 frames ~ 500 m
  const auto again = driftingOdometry(poses, source, OdometryNoise{0.01, 0.005}, 7);
  EXPECT_EQ(again.back(), odo.back());
}

}  // namespace
}  // namespace sglc::sim::test
