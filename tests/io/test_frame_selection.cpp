// The frame-selection grammar every command line shares (sglc/frame_selection.hpp).
#include <gtest/gtest.h>

#include "sglc/frame_selection.hpp"

namespace sglc {
namespace {

TEST(FrameSelection, RangesStridesAndSingles) {
  auto f = FrameSelection::parse("0:300,4300:4541").frames(4541);
  ASSERT_EQ(f.size(), 541u);
  EXPECT_EQ(f.front(), 0);
  EXPECT_EQ(f[299], 299);
  EXPECT_EQ(f[300], 4300);
  EXPECT_EQ(f.back(), 4540);
  f = FrameSelection::parse("0:4541:5").frames(4541);
  ASSERT_EQ(f.size(), 909u);
  EXPECT_EQ(f[1], 5);
  EXPECT_EQ(f.back(), 4540);
  EXPECT_EQ(FrameSelection::parse("52, 4501").frames(4541), (std::vector<int>{52, 4501}));
  EXPECT_EQ(FrameSelection::parse("8:").frames(10), (std::vector<int>{8, 9}));
  EXPECT_EQ(FrameSelection::parse(":2").frames(10), (std::vector<int>{0, 1}));
  EXPECT_EQ(FrameSelection::parse("::4").frames(10), (std::vector<int>{0, 4, 8}));
  EXPECT_EQ(FrameSelection::parse("").frames(3), (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(FrameSelection::parse(":").frames(3), (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(FrameSelection::parse(" 000100 ").frames(200), (std::vector<int>{100}));
}

// contains() answers for frame numbers of a directory whose extent the selection does not know.
TEST(FrameSelection, ContainsFollowsTheSameRules) {
  const auto s = FrameSelection::parse("2:6,10:20:5,4501,6000:");
  for (std::int64_t f : {2, 3, 5, 10, 15, 4501, 6000, 123456}) EXPECT_TRUE(s.contains(f)) << f;
  for (std::int64_t f : {0, 1, 6, 11, 20, 4500, 4502, 5999}) EXPECT_FALSE(s.contains(f)) << f;
  EXPECT_TRUE(FrameSelection().contains(7));
  EXPECT_TRUE(FrameSelection().all());
  EXPECT_EQ(s.text(), "2:6,10:20:5,4501,6000:");
}

TEST(FrameSelection, RejectsBadItemsWithTheirText) {
  for (const char* bad : {"5:3", "a:b", "0:10:0", "3:6,4:8", "1:2:3:4", "7,7", "-1:4", "0:10,", "3:3", "1.5:2", "0:,5",
                          "99999999999999:"}) {
    try {
      FrameSelection::parse(bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("frame selection"), std::string::npos) << e.what();
    }
  }
  // Beyond the sequence: only known once it is listed.
  for (const char* beyond : {"0:99999", "100", "100:"}) {
    const auto s = FrameSelection::parse(beyond);
    try {
      s.frames(100);
      ADD_FAILURE() << "listed '" << beyond << "' in 100 frames";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("only 100 frames"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace sglc
