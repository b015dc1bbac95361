// De-skewing a received scan: the sender's twist, else the constant velocity from the session's previous stored
// scan, else the scan as sent with the reason.
#include <gtest/gtest.h>

#include "closing_test_util.hpp"
#include "sglc/closing/sweep_undo.hpp"

namespace sglc::closing {
namespace {

Mat4d along(double x) {
  Mat4d T = Mat4d::Identity();
  T(0, 3) = x;
  return T;
}

class SweepUndoTest : public ::testing::Test, public test::TwoStreets {
 protected:
  SweepUndoTest() {
    // Session "run" of r1: seq 0 at x = 0 m (t = 10.0 s), seq 3 at x = 0.5 m (t = 10.1 s): 5 m/s, then a scan
    // without a pose, then one 6 s later.
    const auto fp = pipeline.fingerprint(test::viewFrom(test::makeStreetWorld(7), test::kQueryPose));
    const auto add = [&](std::int64_t seq, std::optional<double> stamp, std::optional<Mat4d> pose) {
      store->addScan({.map = "m",
                      .robot = "r1",
                      .session = "run",
                      .seq = seq,
                      .stamp = stamp,
                      .odometry_pose = pose,
                      .fingerprint = &fp});
    };
    add(0, 10.0, along(0.0));
    add(3, 10.1, along(0.5));
    add(20, 11.0, std::nullopt);
    add(30, 20.0, along(9.0));
  }

  static IngestInput input(std::int64_t seq, std::optional<double> stamp, std::optional<Mat4d> pose) {
    IngestInput in;
    in.key = {"m", "r1", "run", seq};
    in.stamp = stamp;
    in.odometry_pose = pose;
    return in;
  }

  // One point 10 m ahead, measured 0.05 s after the stamp; another at the stamp.
  static LabelledScan twoPoints() { return {{Vec3f(10, 0, 0), Vec3f(0, 10, 0)}, {}}; }
  static ScanSweep times() { return {{0.05f, 0.0f}, std::nullopt}; }
};

TEST_F(SweepUndoTest, ScanWithoutTimesIsLeftAlone) {
  auto scan = twoPoints();
  const auto in = input(5, 10.2, along(2.0));
  const auto out = undoSweep({}, scan, store.get(), &in);
  EXPECT_FALSE(out.deskewed);
  EXPECT_FALSE(out.warning);
  EXPECT_EQ(scan.points, twoPoints().points);
}

TEST_F(SweepUndoTest, TheSendersTwistComesFirst) {
  auto scan = twoPoints();
  auto sweep = times();
  sweep.twist = Twist{Eigen::Vector3d(2.0, 0, 0), Eigen::Vector3d::Zero()};  // 2 m/s: the point moves 0.1 m
  const auto in = input(5, 10.2, along(2.0));
  const auto out = undoSweep(sweep, scan, store.get(), &in);
  EXPECT_TRUE(out.deskewed);
  EXPECT_FALSE(out.warning);
  EXPECT_NEAR(scan.points[0].x(), 10.1f, 1e-5f);
  EXPECT_EQ(scan.points[1], Vec3f(0, 10, 0));
}

TEST_F(SweepUndoTest, ConstantVelocityFromThePreviousStoredScan) {
  // seq 5 at x = 2.0 m, t = 10.2 s: the previous stored scan is seq 3 (x = 0.5 m, t = 10.1 s), 15 m/s; seq 0
  // would have given 10 m/s.
  auto scan = twoPoints();
  const auto in = input(5, 10.2, along(2.0));
  const auto out = undoSweep(times(), scan, store.get(), &in);
  ASSERT_TRUE(out.deskewed) << out.warning.value_or("");
  EXPECT_NEAR(scan.points[0].x(), 10.0f + 15.0f * 0.05f, 1e-4f);
  EXPECT_NEAR(scan.points[0].y(), 0.0f, 1e-5f);

  // A retry of seq 3 itself takes seq 0 before it: 5 m/s.
  auto again = twoPoints();
  const auto in3 = input(3, 10.1, along(0.5));
  ASSERT_TRUE(undoSweep(times(), again, store.get(), &in3).deskewed);
  EXPECT_NEAR(again.points[0].x(), 10.0f + 5.0f * 0.05f, 1e-4f);
}

TEST_F(SweepUndoTest, TurningSensorRotatesLatePoints) {
  // The previous scan 0.1 s before, turned 0.1 rad less: 1 rad/s about z. A point 0.05 s late turns 0.05 rad.
  Mat4d turned = along(0.5);
  turned.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  auto scan = twoPoints();
  const auto in = input(4, 10.2, turned);  // turned in place at x = 0.5
  ASSERT_TRUE(undoSweep(times(), scan, store.get(), &in).deskewed);
  EXPECT_NEAR(scan.points[0].x(), 10.0f * std::cos(0.05f), 1e-3f);
  EXPECT_NEAR(scan.points[0].y(), 10.0f * std::sin(0.05f), 1e-3f);
}

TEST_F(SweepUndoTest, WithoutAMotionTheScanStaysAsSentAndSaysWhy) {
  struct Case {
    const char* what;
    IngestInput in;
    const char* reason;
  };
  const Case cases[] = {
      {"no stamp", input(5, std::nullopt, along(2.0)), "no stamp and odometry_pose"},
      {"no pose", input(5, 10.2, std::nullopt), "no stamp and odometry_pose"},
      {"first of its session", input(0, 9.9, along(0.0)), "no earlier scan"},
      {"previous without a pose", input(25, 11.1, along(3.0)), "seq 20) has no stamp or odometry pose"},
      {"previous too long before", input(40, 26.5, along(9.5)), "6.5"},
      {"previous after it in time", input(35, 19.0, along(9.5)), "-1.0"},
      {"an odometry jump of 2 km in 1 s", input(31, 21.0, along(2009.0)), "exceeds 1000 m/s"},
  };
  for (const auto& c : cases) {
    auto scan = twoPoints();
    const auto out = undoSweep(times(), scan, store.get(), &c.in);
    EXPECT_FALSE(out.deskewed) << c.what;
    ASSERT_TRUE(out.warning) << c.what;
    EXPECT_NE(out.warning->find("not de-skewed"), std::string::npos) << *out.warning;
    EXPECT_NE(out.warning->find(c.reason), std::string::npos) << c.what << ": " << *out.warning;
    EXPECT_EQ(scan.points, twoPoints().points) << c.what;
  }
}

TEST_F(SweepUndoTest, AQueryScanNeedsItsTwist) {
  auto scan = twoPoints();
  const auto out = undoSweep(times(), scan);
  EXPECT_FALSE(out.deskewed);
  ASSERT_TRUE(out.warning);
  EXPECT_NE(out.warning->find("the query has no twist"), std::string::npos) << *out.warning;

  auto sweep = times();
  sweep.twist = Twist{Eigen::Vector3d(0, 4.0, 0), Eigen::Vector3d::Zero()};
  EXPECT_TRUE(undoSweep(sweep, scan).deskewed);
  EXPECT_NEAR(scan.points[0].y(), 0.2f, 1e-5f);
}

TEST_F(SweepUndoTest, PreviousScanIsThatOfTheSameSession) {
  // Another session of the same robot and another robot hold nothing before seq 5 of their own.
  auto scan = twoPoints();
  IngestInput other = input(5, 10.2, along(2.0));
  other.key.session = "other";
  EXPECT_FALSE(undoSweep(times(), scan, store.get(), &other).deskewed);
  other.key = {"m", "r2", "run", 5};
  EXPECT_FALSE(undoSweep(times(), scan, store.get(), &other).deskewed);
  EXPECT_EQ(store->previousScan("m", "r1", "run", 3), store->findScan("m", "r1", "run", 0));
  EXPECT_EQ(store->previousScan("m", "r1", "run", 0), std::nullopt);
  EXPECT_EQ(store->previousScan("m", "nobody", "run", 3), std::nullopt);
}

}  // namespace
}  // namespace sglc::closing
