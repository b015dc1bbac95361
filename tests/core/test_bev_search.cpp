// Planar pose from the labelled bird's-eye views alone.
#include <gtest/gtest.h>

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
  LoopResult r = p.verify(q, c);
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
  LoopResult o = Pipeline(off).verify(q, c);
  Pipeline(off).refine(q, c, o, true);
  EXPECT_FALSE(o.refined);
}

}  // namespace
}  // namespace sglc
