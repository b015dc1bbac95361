// ConnectionSlots: the per-peer and total limits of the metrics endpoint, and who gives up a slot.
#include "connection_slots.hpp"

#include <gtest/gtest.h>

namespace sglc::server {
namespace {

TEST(ConnectionSlots, APeerOverItsLimitTakesItsOwnOldestWaitingSlot) {
  ConnectionSlots slots(10, 2);
  const auto a = slots.admit("a"), b = slots.admit("a"), other = slots.admit("b");
  ASSERT_TRUE(a && b && other);
  EXPECT_TRUE(a->evicted.empty() && b->evicted.empty());
  const auto c = slots.admit("a");
  ASSERT_TRUE(c);
  EXPECT_EQ(c->evicted, std::vector<ConnectionSlots::Id>{a->id}) << "a's oldest, not b's connection";
  EXPECT_EQ(slots.open(), 3);
  slots.leave(a->id);  // its owner closes it later: nothing more happens
  EXPECT_EQ(slots.open(), 3);
}

TEST(ConnectionSlots, AFullServerEvictsTheOldestWaitingFromAnyPeer) {
  ConnectionSlots slots(3, 3);
  const auto a = slots.admit("a"), b = slots.admit("b"), c = slots.admit("c");
  slots.requestReceived(a->id);  // being answered: kept
  const auto d = slots.admit("d");
  ASSERT_TRUE(d);
  EXPECT_EQ(d->evicted, std::vector<ConnectionSlots::Id>{b->id});
  EXPECT_EQ(slots.open(), 3);
}

TEST(ConnectionSlots, ANewcomerIsRefusedOnlyWhenEverySlotIsBeingAnswered) {
  ConnectionSlots slots(2, 2);
  const auto a = slots.admit("a"), b = slots.admit("b");
  slots.requestReceived(a->id);
  slots.requestReceived(b->id);
  EXPECT_FALSE(slots.admit("c")) << "full, nobody to evict";
  EXPECT_FALSE(slots.admit("a")) << "a's only slot is busy";
  slots.leave(b->id);
  slots.leave(b->id);  // twice: ignored
  const auto c = slots.admit("c");
  ASSERT_TRUE(c);
  EXPECT_TRUE(c->evicted.empty());
  EXPECT_EQ(slots.open(), 2);
}

TEST(ConnectionSlots, ThePerPeerCountFollowsLeaves) {
  ConnectionSlots slots(10, 1);
  const auto a = slots.admit("a");
  slots.requestReceived(a->id);
  EXPECT_FALSE(slots.admit("a"));
  slots.leave(a->id);
  const auto again = slots.admit("a");
  ASSERT_TRUE(again);
  EXPECT_TRUE(again->evicted.empty());
}

}  // namespace
}  // namespace sglc::server
