// Loop-closure metrics: PR curve, F1max, EP, AUC, Recall@N, pose errors and registration recall.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <set>

#include "metrics.hpp"

namespace sglc::eval {
namespace {

constexpr double kEps = 1e-12;

void expectPoint(const PrPoint& p, double threshold, double precision, double recall, std::size_t tp, std::size_t fp,
                 std::size_t fn) {
  EXPECT_EQ(p.threshold, threshold);
  EXPECT_NEAR(p.precision, precision, kEps);
  EXPECT_NEAR(p.recall, recall, kEps);
  EXPECT_EQ(p.tp, tp);
  EXPECT_EQ(p.fp, fp);
  EXPECT_EQ(p.fn, fn);
}

PrPoint point(double threshold, double precision, double recall) {
  PrPoint p;
  p.threshold = threshold;
  p.precision = precision;
  p.recall = recall;
  return p;
}

// Sequence protocol, 4 queries with a true loop; ties at 0.8 and 0.3. Query 1 matched a wrong candidate
// although a true loop exists. At each threshold (descending):
//   0.9: {0}           TP 1 FP 0 FN 3  P 1    R 1/4
//   0.8: {0,1,2}       TP 2 FP 1 FN 2  P 2/3  R 1/2
//   0.5: {0,1,2,3}     TP 2 FP 2 FN 2  P 1/2  R 1/2
//   0.3: all six       TP 3 FP 3 FN 1  P 1/2  R 3/4   (the FN left is query 1)
std::vector<Decision> sixDecisions() {
  return {{0.8, false, true},  {0.3, true, true}, {0.9, true, true},
          {0.5, false, false}, {0.8, true, true}, {0.3, false, false}};
}

TEST(PrCurve, HandComputedWithTies) {
  const auto curve = prCurve(sixDecisions());
  ASSERT_EQ(curve.size(), 4u);
  expectPoint(curve[0], 0.3, 0.5, 0.75, 3, 3, 1);
  expectPoint(curve[1], 0.5, 0.5, 0.5, 2, 2, 2);
  expectPoint(curve[2], 0.8, 2.0 / 3, 0.5, 2, 1, 2);
  expectPoint(curve[3], 0.9, 1.0, 0.25, 1, 0, 3);
}

TEST(PrCurve, PairProtocolCountsUndetectedPositivesOnly) {
  // Labels double as predictions: FN = positives scoring below the threshold.
  const std::vector<Decision> d = {{0.7, true, true}, {0.6, false, false}, {0.2, true, true}};
  const auto curve = prCurve(d);
  ASSERT_EQ(curve.size(), 3u);
  expectPoint(curve[0], 0.2, 2.0 / 3, 1.0, 2, 1, 0);
  expectPoint(curve[1], 0.6, 0.5, 0.5, 1, 1, 1);
  expectPoint(curve[2], 0.7, 1.0, 0.5, 1, 0, 1);
}

TEST(PrCurve, WrongCandidateIsFalsePositiveAndFalseNegative) {
  // Sequence protocol: query 0 has a true loop but its best candidate is wrong.
  const std::vector<Decision> d = {{0.9, false, true}, {0.6, true, true}, {0.4, false, false}};
  const auto curve = prCurve(d);
  ASSERT_EQ(curve.size(), 3u);
  expectPoint(curve[2], 0.9, 0.0, 0.0, 0, 1, 2);
  expectPoint(curve[1], 0.6, 0.5, 0.5, 1, 1, 1);
  expectPoint(curve[0], 0.4, 1.0 / 3, 0.5, 1, 2, 1);
}

TEST(PrCurve, UndetectableQueriesStillCountAsMissed) {
  // A NaN score is never >= any threshold: no point of its own, but its true loop is missed everywhere.
  const std::vector<Decision> d = {{0.5, true, true}, {std::numeric_limits<double>::quiet_NaN(), false, true}};
  const auto curve = prCurve(d);
  ASSERT_EQ(curve.size(), 1u);
  expectPoint(curve[0], 0.5, 1.0, 0.5, 1, 0, 1);
}

TEST(PrCurve, EmptyAndNoPositives) {
  EXPECT_TRUE(prCurve({}).empty());
  const auto curve = prCurve({{0.4, false, false}, {0.1, false, false}});
  ASSERT_EQ(curve.size(), 2u);
  expectPoint(curve[0], 0.1, 0.0, 0.0, 0, 2, 0);
  expectPoint(curve[1], 0.4, 0.0, 0.0, 0, 1, 0);
}

TEST(PrCurve, SignedZerosAreOneThreshold) {
  const auto a = prCurve({{-0.0, true, true}, {0.0, false, false}});
  const auto b = prCurve({{0.0, false, false}, {-0.0, true, true}});
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_FALSE(std::signbit(a[0].threshold));
  EXPECT_FALSE(std::signbit(b[0].threshold));
  expectPoint(a[0], 0.0, 0.5, 1.0, 1, 1, 0);
}

// Every point recomputed straight from the definition, and independence from the input order.
TEST(PrCurve, MatchesDefinitionAndIgnoresInputOrder) {
  std::mt19937 rng(7);
  std::vector<Decision> d(300);
  for (auto& x : d) {
    x.score = static_cast<double>(rng() % 25) / 25.0;
    x.has_true_loop = rng() % 2 == 0;
    x.predicted_true = x.has_true_loop && rng() % 3 != 0;
  }
  const auto curve = prCurve(d);
  std::set<double> scores;
  for (const auto& x : d) scores.insert(x.score);
  ASSERT_EQ(curve.size(), scores.size());
  auto it = scores.begin();
  for (const auto& p : curve) {
    const double t = *it++;
    std::size_t tp = 0, fp = 0, fn = 0;
    for (const auto& x : d) {
      const bool detected = x.score >= t;
      tp += detected && x.predicted_true;
      fp += detected && !x.predicted_true;
      fn += x.has_true_loop && !(detected && x.predicted_true);
    }
    expectPoint(p, t, double(tp) / double(tp + fp), double(tp) / double(tp + fn), tp, fp, fn);
  }
  std::shuffle(d.begin(), d.end(), rng);
  const auto again = prCurve(d);
  ASSERT_EQ(again.size(), curve.size());
  for (std::size_t i = 0; i < curve.size(); ++i) {
    EXPECT_EQ(again[i].threshold, curve[i].threshold);
    EXPECT_EQ(again[i].precision, curve[i].precision);
    EXPECT_EQ(again[i].recall, curve[i].recall);
  }
}

TEST(PrCurve, MillionsOfDecisions) {
  const std::size_t n = 2'000'000, distinct = 50'000;
  std::vector<Decision> d(n);
  std::size_t positives = 0;
  for (std::size_t i = 0; i < n; ++i) {
    d[i].score = static_cast<double>((i * 7919) % distinct);
    d[i].predicted_true = d[i].has_true_loop = i % 3 == 0;
    positives += d[i].has_true_loop;
  }
  const auto curve = prCurve(d);
  ASSERT_EQ(curve.size(), distinct);
  for (std::size_t k = 1; k < curve.size(); ++k) ASSERT_LT(curve[k - 1].threshold, curve[k].threshold);
  EXPECT_EQ(curve.front().tp + curve.front().fp, n);
  EXPECT_EQ(curve.front().tp, positives);
  EXPECT_EQ(curve.front().fn, 0u);
  EXPECT_EQ(curve.back().tp + curve.back().fp, n / distinct);
}

TEST(F1Max, HandComputed) {
  // F1 per point: 0.3 -> 0.6, 0.5 -> 0.5, 0.8 -> 4/7, 0.9 -> 0.4.
  const auto best = f1Max(prCurve(sixDecisions()));
  EXPECT_NEAR(best.f1, 0.6, kEps);
  EXPECT_EQ(best.threshold, 0.3);
  EXPECT_NEAR(best.precision, 0.5, kEps);
  EXPECT_NEAR(best.recall, 0.75, kEps);
}

TEST(F1Max, EmptyZeroAndTies) {
  const auto empty = f1Max({});
  EXPECT_EQ(empty.f1, 0.0);
  EXPECT_EQ(empty.threshold, 0.0);
  const auto zero = f1Max({point(0.4, 0.0, 0.0), point(0.7, 0.0, 0.0)});
  EXPECT_EQ(zero.f1, 0.0);
  EXPECT_FALSE(std::isnan(zero.f1));
  // Equal F1 (2/3) at both points: the first in curve order, i.e. the lower threshold.
  const auto tie = f1Max({point(0.2, 0.5, 1.0), point(0.8, 1.0, 0.5)});
  EXPECT_NEAR(tie.f1, 2.0 / 3, kEps);
  EXPECT_EQ(tie.threshold, 0.2);
}

TEST(ExtendedPrecision, HandComputed) {
  // Highest threshold 0.9 has P 1; largest recall at P 1 is 1/4.
  EXPECT_NEAR(extendedPrecision(prCurve(sixDecisions())), (1.0 + 0.25) / 2, kEps);
}

TEST(ExtendedPrecision, PrecisionNeverOne) {
  // Top score is a tie of a TP and an FP: P 1/2 at the lowest recall, never 1.
  const auto curve = prCurve({{0.9, true, true}, {0.9, false, false}, {0.5, true, true}});
  ASSERT_EQ(curve.size(), 2u);
  EXPECT_NEAR(curve.back().precision, 0.5, kEps);
  EXPECT_NEAR(extendedPrecision(curve), 0.25, kEps);
}

TEST(ExtendedPrecision, AllCorrectAndEmpty) {
  EXPECT_NEAR(extendedPrecision(prCurve({{0.9, true, true}, {0.7, true, true}, {0.2, true, true}})), 1.0, kEps);
  EXPECT_EQ(extendedPrecision({}), 0.0);
}

TEST(ExtendedPrecision, UsesHighestThresholdWhateverTheOrder) {
  const std::vector<PrPoint> curve = {point(0.5, 0.6, 0.5), point(0.9, 0.8, 0.1), point(0.1, 0.4, 1.0)};
  EXPECT_NEAR(extendedPrecision(curve), 0.4, kEps);
}

TEST(PrAuc, HandComputed) {
  // From (0, 1): (0.25, 1) -> 0.25; (0.5, 2/3) -> 0.25 * (1 + 2/3) / 2 = 5/24; (0.5, 1/2) -> 0;
  // (0.75, 1/2) -> 1/8. Total 7/12.
  EXPECT_NEAR(prAuc(prCurve(sixDecisions())), 7.0 / 12, kEps);
}

TEST(PrAuc, StartsAtPrecisionOfLowestRecallPoint) {
  EXPECT_NEAR(prAuc({point(0.7, 0.5, 0.4)}), 0.2, kEps);
  EXPECT_EQ(prAuc({}), 0.0);
}

TEST(PrAuc, SortsByRecallAndEqualRecallByThresholdDescending) {
  // Sorted: (0.2, 1) [0.9], (0.6, 0.75) [0.7], (0.6, 0.5) [0.6], (0.8, 0.4) [0.1].
  // 0.2 * 1 + 0.4 * (1 + 0.75) / 2 + 0 + 0.2 * (0.5 + 0.4) / 2 = 0.2 + 0.35 + 0.09 = 0.64
  // (the other order of the tie would give 0.615).
  const std::vector<PrPoint> curve = {point(0.6, 0.5, 0.6), point(0.1, 0.4, 0.8), point(0.9, 1.0, 0.2),
                                      point(0.7, 0.75, 0.6)};
  EXPECT_NEAR(prAuc(curve), 0.64, kEps);
}

TEST(RecallAtN, Cases) {
  const std::vector<std::vector<bool>> ranked = {
      {false, true, false},  // hit at rank 2
      {true},                // hit at rank 1
      {false, false},        // never
      {true, false},         // no true loop: skipped although its first candidate is true
      {},                    // true loop, no candidates
  };
  const std::vector<bool> has = {true, true, true, false, true};
  EXPECT_NEAR(recallAtN(ranked, has, 1), 0.25, kEps);
  EXPECT_NEAR(recallAtN(ranked, has, 2), 0.5, kEps);
  EXPECT_NEAR(recallAtN(ranked, has, 100), 0.5, kEps);
  EXPECT_EQ(recallAtN(ranked, has, 0), 0.0);
}

TEST(RecallAtN, NoTrueLoopsAndBadSizes) {
  EXPECT_EQ(recallAtN({{true}, {true}}, {false, false}, 1), 0.0);
  EXPECT_EQ(recallAtN({}, {}, 1), 0.0);
  EXPECT_THROW(recallAtN({{true}}, {true, false}, 1), std::invalid_argument);
}

Mat4d pose(const Eigen::AngleAxisd& r, const Vec3d& t) {
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = r.toRotationMatrix();
  T.topRightCorner<3, 1>() = t;
  return T;
}

double deg(double d) { return d * std::numbers::pi / 180; }

TEST(PoseError, NinetyDegreesAboutZ) {
  const Mat4d est = pose(Eigen::AngleAxisd(0, Vec3d::UnitZ()), Vec3d(1, 2, 3));
  const Mat4d gt = pose(Eigen::AngleAxisd(deg(90), Vec3d::UnitZ()), Vec3d(4, 6, 3));
  const auto e = poseError(est, gt);
  EXPECT_NEAR(e.rte_m, 5.0, kEps);
  EXPECT_NEAR(e.rre_deg, 90.0, 1e-9);
}

TEST(PoseError, FiveDegreesAboutObliqueAxis) {
  const Eigen::AngleAxisd base(deg(37), Vec3d(-0.3, 0.9, 0.2).normalized());
  const Eigen::AngleAxisd delta(deg(5), Vec3d(1, 2, 3).normalized());
  const Mat4d est = pose(base, Vec3d(10, -4, 0.5));
  Mat4d gt = pose(base, Vec3d(10.3, -4.4, 0.5));
  gt.topLeftCorner<3, 3>() = base.toRotationMatrix() * delta.toRotationMatrix();
  const auto e = poseError(est, gt);
  EXPECT_NEAR(e.rte_m, 0.5, 1e-12);
  EXPECT_NEAR(e.rre_deg, 5.0, 1e-9);
  EXPECT_NEAR(poseError(gt, est).rre_deg, 5.0, 1e-9);
}

TEST(PoseError, HalfTurn) {
  const Mat4d gt = pose(Eigen::AngleAxisd(deg(180), Vec3d(2, -1, 1).normalized()), Vec3d::Zero());
  const auto e = poseError(Mat4d::Identity(), gt);
  EXPECT_FALSE(std::isnan(e.rre_deg));
  EXPECT_NEAR(e.rre_deg, 180.0, 1e-5);
}

TEST(PoseError, NearIdentityIsClampedNotNan) {
  // A diagonal entry a few ulps above 1 (as accumulated rounding leaves it) puts (trace - 1) / 2 just above
  // 1, where acos would give NaN. (4 ulps so that the sum stays above 3 in any summation order.)
  Mat4d gt = Mat4d::Identity();
  gt(0, 0) = 1 + 4 * std::numeric_limits<double>::epsilon();
  ASSERT_GT((gt.topLeftCorner<3, 3>().trace() - 1) / 2, 1.0);
  const auto e = poseError(Mat4d::Identity(), gt);
  EXPECT_EQ(e.rre_deg, 0.0);
  EXPECT_EQ(e.rte_m, 0.0);

  // A genuine 1e-9 rad rotation: below what acos resolves near 1, so ~0, and never NaN.
  const Mat4d tiny = pose(Eigen::AngleAxisd(1e-9, Vec3d(1, 1, 1).normalized()), Vec3d::Zero());
  const auto t = poseError(tiny, Mat4d::Identity());
  EXPECT_FALSE(std::isnan(t.rre_deg));
  EXPECT_LT(t.rre_deg, 1e-5);

  // 0.01 deg is still resolved.
  const Mat4d small = pose(Eigen::AngleAxisd(deg(0.01), Vec3d::UnitX()), Vec3d::Zero());
  EXPECT_NEAR(poseError(Mat4d::Identity(), small).rre_deg, 0.01, 1e-7);
}

TEST(PoseError, TranslationIgnoresRotation) {
  const Mat4d est = pose(Eigen::AngleAxisd(deg(30), Vec3d::UnitY()), Vec3d(1, 1, 1));
  const Mat4d gt = pose(Eigen::AngleAxisd(0, Vec3d::UnitY()), Vec3d(1, 1, 1));
  const auto e = poseError(est, gt);
  EXPECT_EQ(e.rte_m, 0.0);
  EXPECT_NEAR(e.rre_deg, 30.0, 1e-9);
  EXPECT_NEAR(poseError(Mat4d::Identity(), pose(Eigen::AngleAxisd(0, Vec3d::UnitY()), Vec3d(0, -3, 4))).rte_m, 5.0,
              kEps);
}

RegistrationResult reg(bool registered, double rte, double rre, bool verified = true) {
  return {registered, {rte, rre}, verified};
}

TEST(RegistrationRecall, StrictLimitsFailuresMeansAndMedians) {
  const std::vector<RegistrationResult> r = {
      reg(true, 0.1, 1.0),   // success
      reg(true, 2.0, 1.0),   // RTE at the limit: failure
      reg(true, 0.5, 5.0),   // RRE at the limit: failure
      reg(false, 0.0, 0.0),  // no pose: failure whatever its error says
      reg(true, 1.9, 4.9),   // success
      reg(true, 0.3, 0.2),   // success
      reg(true, 0.2, 3.0),   // success
  };
  const auto s = registrationRecall(r);
  EXPECT_EQ(s.pairs, 7u);
  EXPECT_EQ(s.successes, 4u);
  EXPECT_NEAR(s.rr, 4.0 / 7, kEps);
  EXPECT_NEAR(s.rte_mean, (0.1 + 1.9 + 0.3 + 0.2) / 4, kEps);
  EXPECT_NEAR(s.rre_mean, (1.0 + 4.9 + 0.2 + 3.0) / 4, kEps);
  EXPECT_NEAR(s.rte_median, (0.2 + 0.3) / 2, kEps);  // 0.1 0.2 | 0.3 1.9
  EXPECT_NEAR(s.rre_median, (1.0 + 3.0) / 2, kEps);  // 0.2 1.0 | 3.0 4.9

  EXPECT_NEAR(s.rr_verified, 4.0 / 7, kEps);  // every pair above was verified
  // A success verification rejected counts in rr, not in rr_verified; a verified failure in neither.
  const auto mixed = registrationRecall({reg(true, 0.1, 1.0, false), reg(true, 0.1, 1.0), reg(true, 3.0, 1.0)});
  EXPECT_NEAR(mixed.rr, 2.0 / 3, kEps);
  EXPECT_NEAR(mixed.rr_verified, 1.0 / 3, kEps);

  // Odd count: the middle value.
  const auto odd = registrationRecall({r[0], r[4], r[5]});
  EXPECT_EQ(odd.successes, 3u);
  EXPECT_NEAR(odd.rte_median, 0.3, kEps);
  EXPECT_NEAR(odd.rre_median, 1.0, kEps);

  // Other limits: RTE < 0.25 keeps 0.1 and 0.2 only.
  const auto tight = registrationRecall(r, 0.25, 10.0);
  EXPECT_EQ(tight.successes, 2u);
  EXPECT_NEAR(tight.rr, 2.0 / 7, kEps);
  EXPECT_NEAR(tight.rte_mean, 0.15, kEps);
  EXPECT_NEAR(tight.rre_median, 2.0, kEps);
}

TEST(RegistrationRecall, NoPairsNoSuccessesAndNan) {
  const auto none = registrationRecall({});
  EXPECT_EQ(none.pairs, 0u);
  EXPECT_EQ(none.rr, 0.0);
  EXPECT_EQ(none.rte_median, 0.0);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const auto fail = registrationRecall({reg(false, 0.1, 0.1), reg(true, 3.0, 0.1), reg(true, nan, 0.1)});
  EXPECT_EQ(fail.pairs, 3u);
  EXPECT_EQ(fail.successes, 0u);
  EXPECT_EQ(fail.rr, 0.0);
  EXPECT_EQ(fail.rte_mean, 0.0);
  EXPECT_EQ(fail.rre_mean, 0.0);
  EXPECT_EQ(fail.rte_median, 0.0);
  EXPECT_EQ(fail.rre_median, 0.0);
}

}  // namespace
}  // namespace sglc::eval

namespace sglc::eval {
namespace {

Mat4d at(double x, double y, double z) {
  Mat4d T = Mat4d::Identity();
  T(0, 3) = x;
  T(1, 3) = y;
  T(2, 3) = z;
  return T;
}

TEST(TrajectoryError, RigidMotionIsFreeAndOffsetsCount) {
  std::vector<Mat4d> gt;
  for (int i = 0; i < 20; ++i) gt.push_back(at(i, 0.1 * i * i, 0));
  EXPECT_NEAR(absoluteTrajectoryError(gt, gt), 0.0, 1e-12);
  Mat4d M = Mat4d::Identity();
  M.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  M.block<3, 1>(0, 3) = Eigen::Vector3d(5, -3, 2);
  std::vector<Mat4d> moved;
  for (const auto& T : gt) moved.push_back(M * T);
  EXPECT_NEAR(absoluteTrajectoryError(moved, gt), 0.0, 1e-9);  // the alignment removes a rigid motion
  // On a line along x, +-0.1 m up and down in the pattern + - - + + - - + is uncorrelated with x: no rigid
  // motion reduces it, RMSE 0.1 m.
  std::vector<Mat4d> line, wobble;
  for (int i = 0; i < 8; ++i) {
    line.push_back(at(i, 0, 0));
    wobble.push_back(at(i, 0, (i % 4 == 0 || i % 4 == 3) ? 0.1 : -0.1));
  }
  EXPECT_NEAR(absoluteTrajectoryError(wobble, line), 0.1, 1e-9);
  std::vector<Eigen::Vector3d> aligned;
  absoluteTrajectoryError(moved, gt, &aligned);
  ASSERT_EQ(aligned.size(), gt.size());
  EXPECT_LT((aligned[7] - gt[7].block<3, 1>(0, 3)).norm(), 1e-9);
  EXPECT_THROW(absoluteTrajectoryError({}, {}), InputError);
  EXPECT_THROW(absoluteTrajectoryError(gt, line), InputError);  // 20 vs 8 poses
}

}  // namespace
}  // namespace sglc::eval
