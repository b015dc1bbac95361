// Two servers on one PostgreSQL map: one solves the pose graph, the other follows its versions, and takes the
// map over when the first stops.
#include <gtest/gtest.h>

#include "../storage/backend.hpp"
#include "drive.hpp"

namespace sglc::posegraph {
namespace {

using namespace std::chrono_literals;
using testing::drive;
using testing::driveOptions;

TEST(Replicas, OneServerSolvesAMapTheOtherFollowsAndTakesOverWhenItStops) {
  storage::testing::Backend db("postgresql");
  if (!db.unavailable().empty()) GTEST_SKIP() << db.unavailable();
  auto store_a = db.open();
  auto store_b = db.open();
  const auto d = drive(*store_a);
  auto options = driveOptions();
  options.replica_poll_s = 0.1;
  options.debounce = 20ms;
  auto a = std::make_unique<GraphOptimiser>(*store_a, options);
  const auto first = a->waitForVersion("m", 0, 120s);  // a starts first: it holds the map
  ASSERT_TRUE(first && !first->failed);
  EXPECT_EQ(first->nodes, 240);
  const auto map_id = store_a->findMap("m")->id;
  EXPECT_FALSE(store_b->claimGraph(map_id));

  GraphOptimiser b(*store_b, options);
  const auto followed = b.waitForVersion("m", 0, 120s);  // b follows a's stored version, solving nothing
  ASSERT_TRUE(followed && !followed->failed);
  EXPECT_EQ(followed->nodes, 0);
  EXPECT_GE(followed->graph_version, first->graph_version);

  // A loop stored through b: a finds it on its next poll and solves it; b follows the new version.
  const auto before = store_b->graphVersion("m");
  store_b->addLoop("m", {0, d.ids[200], d.ids[80], d.gt[200].inverse() * d.gt[80], 0.8, 0.9, 0.02, 20});
  b.loopsAdded("m");
  const auto solved_by_a = a->waitForVersion("m", before, 120s);
  ASSERT_TRUE(solved_by_a && !solved_by_a->failed);
  EXPECT_GT(solved_by_a->nodes, 0);
  ASSERT_TRUE(b.waitForVersion("m", solved_by_a->graph_version - 1, 120s));

  // a stops (its store closes, and its lock with it): b takes the map over and solves it itself.
  const auto version = store_b->graphVersion("m");
  a.reset();
  store_a.reset();
  std::optional<GraphEvent> taken;
  for (auto after = version; !taken;) {
    const auto e = b.waitForVersion("m", after, 120s);
    ASSERT_TRUE(e && !e->failed);
    if (e->nodes > 0) taken = e;  // a solve of b's own, not a followed version
    after = e->graph_version;
  }
  EXPECT_EQ(taken->nodes, 240);
  EXPECT_TRUE(store_b->claimGraph(map_id));
  EXPECT_LT(testing::ate(testing::optimised(*store_b), d.gt), 0.2);
}

}  // namespace
}  // namespace sglc::posegraph
