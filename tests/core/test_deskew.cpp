// De-skewing a sweep (sglc/deskew.hpp).
#include <gtest/gtest.h>

#include "sglc/deskew.hpp"
#include "test_util.hpp"

using namespace sglc;
using sglc::test::makeT;

TEST(Deskew, TwistBetweenPosesAndBack) {
  const Mat4d from = makeT(30, 5, -2, 1.7);
  const Mat4d step = makeT(4, 1.2, 0.1, 0.02);
  const Twist t = twistBetween(from, from * step, 0.1);
  EXPECT_NEAR(t.linear.x(), 12.0, 1e-9);
  EXPECT_NEAR(t.angular.z(), test::deg2rad(4) / 0.1, 1e-9);
  // The motion over the whole gap is the step again.
  EXPECT_TRUE(motionAt(t, 0.1).isApprox(step, 1e-12));
  EXPECT_TRUE(motionAt(t, 0.0).isApprox(Mat4d::Identity(), 1e-15));
  EXPECT_THROW(twistBetween(from, from, 0.0), InputError);
  EXPECT_THROW(twistBetween(from, from, std::nan("")), InputError);
}

TEST(Deskew, PointsMeasuredDuringTheSweepReturnToTheStampFrame) {
  // A sensor turning 20 deg/s and driving 10 m/s; each world point measured at its own time.
  Twist twist;
  twist.linear = Eigen::Vector3d(10, 0.5, 0);
  twist.angular = Eigen::Vector3d(0, 0, test::deg2rad(20));
  Points truth, measured;
  std::vector<float> times;
  for (int i = 0; i < 360; ++i) {
    const float t = 0.1f * static_cast<float>(i) / 360.0f;
    const Vec3f p(20.0f * std::cos(i * 0.0174f), 20.0f * std::sin(i * 0.0174f), 0.3f * (i % 7));
    truth.push_back(p);
    // The sensor at t is at motionAt(t) in the stamp's frame: the point in the sensor's frame then.
    measured.push_back(test::apply(Mat4d(motionAt(twist, t).inverse()), p));
    times.push_back(t);
  }
  Points fixed = measured;
  deskew(fixed, times, twist);
  double worst = 0, before = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    worst = std::max(worst, static_cast<double>((fixed[i] - truth[i]).norm()));
    before = std::max(before, static_cast<double>((measured[i] - truth[i]).norm()));
  }
  EXPECT_LT(worst, 1e-4);
  EXPECT_GT(before, 0.9);  // 10 m/s over 0.1 s, and the turn at 20 m

  // The twist from poses: the previous scan's motion when there is no next one.
  const TimedPose a{0.0, makeT(0, 0, 0, 0)}, b{0.1, makeT(2, 1, 0, 0)}, c{0.2, makeT(5, 2.5, 0, 0)};
  EXPECT_NEAR(sweepTwist(&a, b, &c).linear.x(), (b.pose.inverse() * c.pose)(0, 3) / 0.1, 1e-9);
  EXPECT_NEAR(sweepTwist(&a, b, nullptr).linear.x(), 10.0, 1e-9);
  EXPECT_THROW(sweepTwist(nullptr, b, nullptr), InputError);
}

TEST(Deskew, BadTimesAreRefused) {
  Points p{{1, 2, 3}, {4, 5, 6}};
  EXPECT_THROW(deskew(p, {0.0f}, {}), InputError);
  Twist moving;
  moving.linear.x() = 10;
  EXPECT_THROW(deskew(p, {0.05f, std::nanf("")}, moving), InputError);
  EXPECT_THROW(deskew(p, {0.0f, 5.0f}, {}), InputError);
  Twist bad;
  bad.linear.x() = std::nan("");
  EXPECT_THROW(deskew(p, {0.0f, 0.0f}, bad), InputError);
  // Finite but beyond any vehicle: 1e38 m/s would send the points to infinity.
  Twist fast;
  fast.linear.x() = 1e38;
  EXPECT_NE(twistError(fast).find("speed"), std::string::npos) << twistError(fast);
  EXPECT_THROW(deskew(p, {0.05f, 0.0f}, fast), InputError);
  Twist spin;
  spin.angular.z() = kMaxSweepTurnRate * 1.01;
  EXPECT_NE(twistError(spin).find("turn rate"), std::string::npos);
  spin.angular.z() = kMaxSweepTurnRate;
  EXPECT_EQ(twistError(spin), "");
  EXPECT_EQ(p[1], Vec3f(4, 5, 6));  // untouched by the refusals
}
