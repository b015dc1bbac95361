// Revisits: the same landmarks seen again from another viewpoint, and the engine closing the loop on them.
#include "sglc/pipeline.hpp"
#include "sim/ground_truth.hpp"
#include "sim_test_util.hpp"

namespace sglc::sim::test {
namespace {

// The closest pair (earlier, later) of the trajectory whose headings differ by less than 30 deg (same
// direction) or more than 150 deg (reverse), at least 300 frames apart.
std::pair<int, int> closestRevisit(const Trajectory& t, bool reverse) {
  std::vector<int> source(t.poses.size());
  for (std::size_t k = 0; k < source.size(); ++k) source[k] = static_cast<int>(k);
  double best = 1e9;
  std::pair<int, int> out{-1, -1};
  for (const auto& r : loopPoses(t.poses, source, 3.0, 300)) {
    const double h = headingDifferenceDeg(t.poses[r.first], t.poses[r.second]);
    if (reverse ? h < 150 : h > 30) continue;
    const double d = r.T.topRightCorner<3, 1>().norm();
    if (d < best) {
      best = d;
      out = {r.first, r.second};
    }
  }
  return out;
}

double sharedShare(const Frame& a, const Frame& b, int min_points) {
  const auto la = landmarkInstances(a, min_points), lb = landmarkInstances(b, min_points);
  std::vector<std::uint32_t> common;
  std::set_intersection(la.begin(), la.end(), lb.begin(), lb.end(), std::back_inserter(common));
  return static_cast<double>(common.size()) / std::max<std::size_t>(1, std::min(la.size(), lb.size()));
}

SimConfig noiseFree(int beams, int columns) {
  SimConfig cfg;
  cfg.sensor = SensorConfig::preset(beams);
  cfg.sensor.columns = columns;
  cfg.sensor.noiseFree();
  return cfg;
}

TEST(Revisit, LoopRouteRevisitsShareMostLandmarks) {
  const Simulator sim(loopTrajectory(), noiseFree(32, 900));
  for (bool reverse : {false, true}) {
    const auto [i, j] = closestRevisit(loopTrajectory(), reverse);
    ASSERT_GE(i, 0) << (reverse ? "no reverse revisit" : "no same-direction revisit");
    SCOPED_TRACE(std::string(reverse ? "reverse" : "same direction") + " revisit " + std::to_string(i) + " / " +
                 std::to_string(j));
    const Frame a = sim.render(i), b = sim.render(j);
    ASSERT_GE(landmarkInstances(a, 5).size(), 8u);
    EXPECT_GT(sharedShare(a, b, 5), 0.6);
  }
}

// The engine on a noise-free revisit: detected, and the relative pose within 0.05 m / 0.2 deg.
void expectLoopClosed(const Simulator& sim, int candidate, int query) {
  const Pipeline pipeline;
  const Frame c = sim.render(candidate), q = sim.render(query);
  const Mat4d gt = q.pose.inverse() * c.pose;  // maps candidate points into the query frame
  const LoopResult r = pipeline.match(pipeline.fingerprint(q.scan), pipeline.fingerprint(c.scan));
  const double te = translationError(r.T, gt), re = rotationErrorDeg(r.T, gt);
  std::cout << "[ engine   ] query " << query << " candidate " << candidate << ": is_loop " << r.is_loop << ", matches "
            << r.matches << ", inliers " << r.inliers << ", score " << r.score << ", |t_gt| "
            << gt.topRightCorner<3, 1>().norm() << " m, error " << te << " m / " << re << " deg" << std::endl;
  EXPECT_GT(sharedShare(c, q, 5), 0.6);
  EXPECT_TRUE(r.is_loop) << r.reason;
  EXPECT_LT(te, 0.05);
  EXPECT_LT(re, 0.2);
}

TEST(Revisit, EngineClosesKitti00LoopWithExactPose) {
  SGLC_REQUIRE_KITTI("00");
  // KITTI 00 frames 52 and 4501 are 2.96 m apart, 4449 frames apart in time (the real loop pair in
  // ../shared/data/semantickitti_scans).
  const Simulator sim(kittiSequence("00"), noiseFree(64, 2083));
  expectLoopClosed(sim, 52, 4501);
}

// The same KITTI 00 pair in the worlds of seeds 1..10, noise-free. Once a documented failure (only 2 of 10
// seeds within 0.05 m / 0.2 deg): the instance ICP biased the pose and the plane stage, anchored by its pairs in
// every direction, kept the bias. The anchor now acts only where the planes leave a direction free.
TEST(Revisit, EnginePoseWithinToleranceOnEverySeed) {
  SGLC_REQUIRE_KITTI("00");
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    SimConfig cfg = noiseFree(64, 2083);
    cfg.seed = seed;
    const Simulator sim(kittiSequence("00"), cfg);
    expectLoopClosed(sim, 52, 4501);
  }
}

// A reverse revisit of the built-in route: the instance ICP pairs opposite sides of trunks and poles; the plane
// stage must not inherit that bias (it did, 0.22 deg, before the anchor became degeneracy-aware).
TEST(Revisit, EngineClosesReverseLoopWithExactPose) {
  const auto [i, j] = closestRevisit(loopTrajectory(), true);
  ASSERT_GE(i, 0);
  const Simulator sim(loopTrajectory(), noiseFree(64, 2083));
  expectLoopClosed(sim, i, j);
}

// The world of seed 7 with a default sensor of `beams`, noise and all (as `sglc-eval --sim` renders it).
SimConfig seven(int beams) {
  SimConfig cfg;
  cfg.seed = 7;
  cfg.sensor = SensorConfig::preset(beams);
  return cfg;
}

// A frame's fingerprint with its labels removed: the built-in labeller computes them.
Fingerprint unlabelledFingerprint(const Simulator& sim, const Pipeline& pipeline, int frame) {
  LabelledScan scan = sim.render(frame).scan;
  scan.labels.clear();
  return pipeline.fingerprint(scan);
}

// Known loops on a straight street of KITTI 00 whose facades repeat every few metres (seed 7, labels removed, as
// `sglc-eval --protocol pose --no-labels` registers them). Verification rejects each pair, so the pose comes from
// the background overlays; the one explaining most planes lay 3.5-5.7 m along the street in the first three, and
// choosing by background agreement alone puts the last one 10 m off: the choice weighs both and how tightly the
// planes fit.
TEST(Revisit, KnownLoopsOnARepeatedStreetArePosedAtThePlace) {
  SGLC_REQUIRE_KITTI("00");
  const Simulator sim(kittiSequence("00"), seven(64));
  // Verification refuses every pair (no probability reaches 1), as it refused these with the bars before the loop
  // model: the pose must come from the known-loop path's overlays.
  Config refusing;
  refusing.verify.min_probability = 1.0;
  const Pipeline pipeline(refusing);
  auto unlabelled = [&](int f) { return unlabelledFingerprint(sim, pipeline, f); };
  for (const auto& [query, candidate] : {std::pair{643, 3594}, {645, 3595}, {652, 3607}, {645, 3596}}) {
    SCOPED_TRACE("pair " + std::to_string(query) + " / " + std::to_string(candidate));
    const Fingerprint q = unlabelled(query), c = unlabelled(candidate);
    const Mat4d gt = sim.trajectory().poses[query].inverse() * sim.trajectory().poses[candidate];
    LoopResult r = pipeline.verify(q, c);
    ASSERT_FALSE(r.is_loop);  // else the pose would not come from the overlays
    pipeline.refine(q, c, r, /*known_loop=*/true);
    ASSERT_TRUE(r.refined);
    EXPECT_LT(translationError(r.T, gt), 0.5) << r.T;
    EXPECT_LT(rotationErrorDeg(r.T, gt), 1.0) << r.T;
  }
}

// A loop verified on 4 landmarks (KITTI 00 frames 717 / 3660, seed 7, 32 beams, labels removed) whose instance
// ICP slid 1.1 m and 7 deg off the coarse pose; the planes, anchored on its point pairs, stayed there with an RMSE
// of 0.29 m. The fine stage is now dropped when it leads the planes to a fit looser than refine.max_rmse_m.
TEST(Revisit, AFineStageThatLeadsThePlanesAstrayIsDropped) {
  SGLC_REQUIRE_KITTI("00");
  const Simulator sim(kittiSequence("00"), seven(32));
  const Pipeline pipeline;
  const Fingerprint q = unlabelledFingerprint(sim, pipeline, 717), c = unlabelledFingerprint(sim, pipeline, 3660);
  const Mat4d gt = sim.trajectory().poses[717].inverse() * sim.trajectory().poses[3660];
  const LoopResult r = pipeline.match(q, c);
  ASSERT_TRUE(r.is_loop) << r.reason;
  ASSERT_TRUE(r.refined);
  EXPECT_LT(translationError(r.T, gt), 0.1) << r.T;
  EXPECT_LT(rotationErrorDeg(r.T, gt), 0.5) << r.T;
  EXPECT_LE(r.rmse, pipeline.config().refine.max_rmse_m);
}

}  // namespace
}  // namespace sglc::sim::test
