// The loop model's probability in the pose graph: a less probable loop gets a narrower robust loss, so the same
// false loop pulls the trajectory less at a low probability than at p = 1; loops without one behave as before.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <optional>

#include "../storage/storage_test_util.hpp"
#include "drive.hpp"
#include "loop_weight.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"

namespace sglc::posegraph {
namespace {

using storage::testing::options;
using storage::testing::TempDir;
using testing::ate;
using testing::drive;
using testing::driveOptions;
using testing::optimised;
using testing::pose;

TEST(LoopLossFactor, UnknownAndTrustedAreOneAndLessProbableIsNarrower) {
  EXPECT_EQ(loopLossFactor(std::nullopt, 0.95), 1.0);
  EXPECT_EQ(loopLossFactor(0.95, 0.95), 1.0);
  EXPECT_EQ(loopLossFactor(1.0, 0.95), 1.0);
  EXPECT_EQ(loopLossFactor(0.3, 0.0), 1.0);  // 0: the probability is not used
  // factor^2 = odds(p) / odds(trusted): 0.5 has odds 1, 0.95 odds 19.
  EXPECT_NEAR(loopLossFactor(0.5, 0.95), std::sqrt(1.0 / 19.0), 1e-12);
  double last = 0;
  for (const double p : {0.0, 0.1, 0.5, 0.7, 0.9, 0.94}) {
    const double f = loopLossFactor(p, 0.95);
    EXPECT_GT(f, last) << p;  // positive (a Cauchy loss needs a scale) and growing with p
    EXPECT_LT(f, 1.0) << p;
    last = f;
  }
}

// The largest position difference between two trajectories (m).
double maxShift(const std::vector<Mat4d>& a, const std::vector<Mat4d>& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, (a[i].block<3, 1>(0, 3) - b[i].block<3, 1>(0, 3)).norm());
  return m;
}

// The drive optimised with its true loops (of `true_p`), then with one false loop of probability `false_p` added:
// the trajectory before and after.
std::pair<std::vector<Mat4d>, std::vector<Mat4d>> withFalseLoop(std::optional<double> true_p,
                                                                std::optional<double> false_p, double* ate_after) {
  TempDir dir;
  auto store = storage::MapStore::open(options(dir.file("map.db")));
  const auto d = drive(*store);
  if (true_p) {  // the drive's loops again, now with a probability (the same pair replaces the first)
    for (const auto& l : store->loops("m")) {
      auto r = l;
      r.probability = true_p;
      store->addLoop("m", r);
    }
  }
  GraphOptimiser graph(*store, driveOptions());
  graph.optimiseNow("m", GraphOptimiser::Scope::kGlobal);
  const auto before = optimised(*store);
  // Scan 200 claimed to be 3 m from scan 20 (they are about 70 m apart): a look-alike place.
  storage::LoopRecord bad{0, d.ids[200], d.ids[20], pose(0.0, 3.0, 0.0), 0.9, 0.9, 0.02, 30};
  bad.probability = false_p;
  store->addLoop("m", bad);
  graph.optimiseNow("m", GraphOptimiser::Scope::kGlobal);
  const auto after = optimised(*store);
  *ate_after = ate(after, d.gt);
  return {before, after};
}

TEST(LoopProbability, ALowProbabilityFalseLoopMovesTheTrajectoryLessThanAtOne) {
  double ate_one = 0, ate_low = 0, ate_unknown = 0;
  const auto [before_one, after_one] = withFalseLoop(1.0, 1.0, &ate_one);
  const auto [before_low, after_low] = withFalseLoop(1.0, 0.6, &ate_low);
  const auto [before_unknown, after_unknown] = withFalseLoop(std::nullopt, std::nullopt, &ate_unknown);
  const double shift_one = maxShift(before_one, after_one), shift_low = maxShift(before_low, after_low);
  std::cout << "false loop at p = 1: max shift " << shift_one << " m, ATE " << ate_one
            << " m; at p = 0.6: " << shift_low << " m, ATE " << ate_low << " m\n";
  // At p = 1 the robust loss already discounts a loop 70 m off (it moves the trajectory by about 0.2 mm); the
  // narrower loss of p = 0.6 (scale x 0.41 under the default trusted probability 0.9) discounts it about 6 times
  // more. The ATEs differ by less than their
  // noise either way: the shift is what the probability changes.
  EXPECT_GT(shift_one, 1e-5);
  EXPECT_LT(shift_low, 0.25 * shift_one);
  // Loops at p = 1 and loops of unknown probability are the same edges: the same solution.
  EXPECT_EQ(before_one.size(), before_unknown.size());
  EXPECT_LT(maxShift(before_one, before_unknown), 1e-9);
  EXPECT_LT(maxShift(after_one, after_unknown), 1e-9);
}

}  // namespace
}  // namespace sglc::posegraph
