// Planar pose from the labelled bird's-eye views alone.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numbers>

#include "sglc/bev_search.hpp"
#include "sglc/pipeline.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using test::rotationErrorDeg;
using test::translationError;

// The street without its landmarks (background only), so nothing but the views can align it.
LabelledScan backgroundOnly(LabelledScan scan) {
  for (auto& l : scan.labels)
    if (l == test::kCar || l == test::kTrunk || l == test::kPole) l = test::kUnlabelled;
  return scan;
}

TEST(BevSearch, RecoversHeadingAndShiftAtAnyHeading) {
  const Pipeline p;
  const LabelledScan world = test::makeStreetWorld();
  const Fingerprint q = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
  for (const double yaw : {0.0, 37.0, 130.0, -100.0, 180.0}) {
    const Mat4d T = test::makeT(yaw, 3.0, -2.0, 0.0);  // the candidate's pose in the query's frame
    const Fingerprint c = p.fingerprint(test::viewFrom(world, T));
    const auto found = searchBevPose(q.background, c.background, q.background_cell, p.config().bev_search);
    ASSERT_FALSE(found.empty());
    ASSERT_LE(static_cast<int>(found.size()), p.config().bev_search.keep);
    for (std::size_t k = 1; k < found.size(); ++k) EXPECT_GE(found[k - 1].score, found[k].score);
    EXPECT_LT(translationError(found[0].T, T), 0.5) << "yaw " << yaw << "\n" << found[0].T;
    EXPECT_LT(rotationErrorDeg(found[0].T, T), 1.0) << "yaw " << yaw << "\n" << found[0].T;
    EXPECT_GT(found[0].score, 0.5);
  }
}

TEST(BevSearch, DeterministicAndEmptyWithoutStructure) {
  const Pipeline p;
  const LabelledScan world = test::makeStreetWorld();
  const Fingerprint q = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
  const Fingerprint c = p.fingerprint(test::viewFrom(world, test::makeT(70.0, -4.0, 1.5, 0.0)));
  const auto a = searchBevPose(q.background, c.background, q.background_cell, p.config().bev_search);
  const auto b = searchBevPose(q.background, c.background, q.background_cell, p.config().bev_search);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].T, b[k].T);
    EXPECT_EQ(a[k].score, b[k].score);
  }
  // Road alone says nothing about a shift: no overlay is proposed.
  LabelledScan road;
  test::addPoints(road, test::makeFloor(-30, 30, -7, 7, -1.7, 0.4), test::kRoad);
  const Fingerprint r = p.fingerprint(road);
  EXPECT_TRUE(searchBevPose(r.background, c.background, r.background_cell, p.config().bev_search).empty());
  EXPECT_TRUE(searchBevPose(q.background, r.background, q.background_cell, p.config().bev_search).empty());
  EXPECT_TRUE(searchBevPose({}, {}, 0.5, p.config().bev_search).empty());
}

// A known loop the landmarks cannot align is registered from the background when the caller says it is a loop,
// and only then; the loop decision stays verification's.
TEST(BevSearch, KnownLoopWithoutLandmarksIsRegisteredFromTheBackground) {
  const Pipeline p;
  const LabelledScan world = backgroundOnly(test::makeStreetWorld());
  const Mat4d T = test::makeT(150.0, 2.5, 1.0, 0.05);
  const Fingerprint q = p.fingerprint(test::viewFrom(world, Mat4d::Identity()));
  const Fingerprint c = p.fingerprint(test::viewFrom(world, T));
  LoopResult r = p.verify(q, c, /*background=*/false);
  ASSERT_FALSE(r.is_loop);
  EXPECT_STREQ(r.reason, "fewer than 3 node matches");
  p.refine(q, c, r);
  EXPECT_FALSE(r.refined);
  EXPECT_EQ(r.T, Mat4d::Identity());
  p.refine(q, c, r, /*known_loop=*/true);
  ASSERT_TRUE(r.refined);
  EXPECT_FALSE(r.is_loop);
  EXPECT_STREQ(r.reason, "fewer than 3 node matches");
  EXPECT_LT(translationError(r.T, T), 0.3) << r.T;
  EXPECT_LT(rotationErrorDeg(r.T, T), 0.5) << r.T;
  EXPECT_GT(r.fitness, 0.5);
  // Switched off: no pose.
  Config off;
  off.bev_search.enabled = false;
  LoopResult o = Pipeline(off).verify(q, c, /*background=*/false);
  Pipeline(off).refine(q, c, o, true);
  EXPECT_FALSE(o.refined);
}

// Vertical planes with their normals at the given headings (degrees), one per entry, and a ground plane.
std::vector<Plane> walls(const std::vector<double>& headings_deg) {
  std::vector<Plane> out;
  for (const double h : headings_deg) {
    Plane p;
    const double r = h * std::numbers::pi / 180.0;
    p.normal = Vec3f(static_cast<float>(std::cos(r)), static_cast<float>(std::sin(r)), 0.05f).normalized();
    out.push_back(p);
  }
  out.push_back(Plane{});  // the ground: normal up, no heading
  return out;
}

double degrees(double rad) { return rad * 180.0 / std::numbers::pi; }

TEST(WallHeadings, TurnTheCandidatesWallsOntoTheQuerys) {
  // A street of square walls (10 and 100 deg), seen again turned by 37 deg: the candidate's normals are the
  // query's minus 37 deg, some of them flipped (the wall seen from its other side).
  const auto q = walls({10, 10, 10, 100, 100, 190});
  const auto c = walls({-27, 153, -27, 63, 63, 243});
  const auto h = wallHeadings(q, c, 2);
  ASSERT_EQ(h.size(), 4u);  // two peaks, each as h and h + 180
  EXPECT_NEAR(degrees(h[0]), 37.0, 1.0);
  EXPECT_NEAR(degrees(h[1]), 217.0, 1.0);
  // The second peak is the square walls' cross match, 90 deg off.
  EXPECT_NEAR(std::abs(std::remainder(degrees(h[2]) - 37.0, 180.0)), 90.0, 1.0);
  for (const double a : h) {
    EXPECT_GE(a, 0.0);
    EXPECT_LT(a, 2.0 * std::numbers::pi);
  }
  EXPECT_EQ(wallHeadings(q, c, 2), h);  // deterministic
  EXPECT_EQ(wallHeadings(q, c, 1).size(), 2u);
  // No wall in either scan (the ground only): nothing to say.
  EXPECT_TRUE(wallHeadings(q, {Plane{}}, 2).empty());
  EXPECT_TRUE(wallHeadings({}, c, 2).empty());
}

// The street seen from the origin (q) and from a pose turned by 130 deg and shifted (c, at T in q's frame).
struct TurnedStreet {
  Pipeline p;
  Mat4d T = test::makeT(130.0, 3.0, -2.0, 0.0);
  Fingerprint q = p.fingerprint(test::viewFrom(test::makeStreetWorld(), Mat4d::Identity()));
  Fingerprint c = p.fingerprint(test::viewFrom(test::makeStreetWorld(), T));
  double true_yaw = 130.0 * std::numbers::pi / 180.0;
};

TEST(BevSearch, RestrictedHeadingsFindThePoseOnlyWhereItIs) {
  const TurnedStreet s;
  const auto& [p, T, q, c, true_yaw] = s;
  // Given the true heading (and a wrong one), the coarse overlay alone is within a cell and a heading step.
  const auto coarse = searchBevPose(q.background, c.background, q.background_cell, p.config().bev_search,
                                    {true_yaw, true_yaw + 1.0}, /*fine=*/false);
  ASSERT_FALSE(coarse.empty());
  EXPECT_LT(translationError(coarse[0].T, T), p.config().bev_search.cell_m * 1.5) << coarse[0].T;
  EXPECT_LT(rotationErrorDeg(coarse[0].T, T), p.config().bev_search.yaw_step_deg * 1.5) << coarse[0].T;
  // Given only headings far from the truth, no proposal is near it.
  const auto wrong = searchBevPose(q.background, c.background, q.background_cell, p.config().bev_search,
                                   {true_yaw + 1.0, true_yaw - 1.2}, false);
  ASSERT_FALSE(wrong.empty());  // the best overlays at the headings it was given, poor as they are
  for (const auto& h : wrong) EXPECT_GT(rotationErrorDeg(h.T, T), 40.0) << h.T;
}

// Several shifts at each heading (a narrow view's search: along a street, shifts score alike): the best one is
// the single-shift search's, no heading step gives more than asked, and some give more than one.
TEST(BevSearch, SeveralShiftsPerHeading) {
  const TurnedStreet s;
  const auto& [p, T, q, c, true_yaw] = s;
  BevSearchConfig all = p.config().bev_search;
  all.keep = 1000;
  const auto one = searchBevPose(q.background, c.background, q.background_cell, all, {true_yaw}, false);
  const auto three = searchBevPose(q.background, c.background, q.background_cell, all, {true_yaw}, false, 3);
  ASSERT_FALSE(one.empty());
  EXPECT_GT(three.size(), one.size());
  EXPECT_EQ(three[0].T, one[0].T);
  EXPECT_EQ(three[0].score, one[0].score);
  std::map<long, int> per_step;  // coarse heading (0.001 deg) -> overlays at it
  for (std::size_t a = 0; a < three.size(); ++a) {
    if (a > 0) EXPECT_GE(three[a - 1].score, three[a].score);
    ++per_step[std::lround(std::atan2(three[a].T(1, 0), three[a].T(0, 0)) * 180e3 / std::numbers::pi)];
  }
  int several = 0;
  for (const auto& [step, n] : per_step) {
    EXPECT_LE(n, 3) << step;
    several += n > 1;
  }
  EXPECT_GT(several, 0);
  const auto again = searchBevPose(q.background, c.background, q.background_cell, all, {true_yaw}, false, 3);
  ASSERT_EQ(again.size(), three.size());
  for (std::size_t k = 0; k < again.size(); ++k) EXPECT_EQ(again[k].T, three[k].T);
}

}  // namespace
}  // namespace sglc
