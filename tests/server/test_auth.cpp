// The bearer token file (TokenTable::load): grants per token, and map names with any bytes through
// percent-escapes.
#include <gtest/gtest.h>

#include <fstream>

#include "auth.hpp"
#include "rpc_error.hpp"
#include "test_util.hpp"

namespace sglc::server {
namespace {

TokenTable load(const test::TempDir& dir, const std::string& text) {
  const std::string path = dir.file("tokens.txt");
  std::ofstream(path) << text;
  return TokenTable::load(path);
}

std::string loadError(const test::TempDir& dir, const std::string& text) {
  try {
    load(dir, text);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

TEST(TokenTable, PlainFilesKeepTheirMeaning) {
  test::TempDir dir;
  const auto t = load(dir, "# comment\nadmin-token-1 *\nfleet-token-2 m1,m2  # two maps\nodd-token-3 50%off\n");
  EXPECT_TRUE(t.grantOf("admin-token-1").all);
  const auto fleet = t.grantOf("fleet-token-2");
  EXPECT_FALSE(fleet.all);
  EXPECT_TRUE(fleet.allows("m1") && fleet.allows("m2") && !fleet.allows("m3"));
  EXPECT_TRUE(t.grantOf("odd-token-3").allows("50%off"));  // a '%' without two hex digits is itself
  EXPECT_THROW(t.grantOf("nobody-token"), RpcError);
}

TEST(TokenTable, PercentEscapesNameMapsWithCommasHashesSpacesAndStars) {
  test::TempDir dir;
  const auto t = load(dir, "token-one-1 a%2Cb,c%23d,with%20space,100%25,%2A\n");
  const auto g = t.grantOf("token-one-1");
  EXPECT_FALSE(g.all) << "a map named '*' is not every map";
  for (const char* map : {"a,b", "c#d", "with space", "100%", "*"}) EXPECT_TRUE(g.allows(map)) << map;
  for (const char* map : {"a", "b", "c", "a%2Cb", "with"}) EXPECT_FALSE(g.allows(map)) << map;
}

TEST(TokenTable, NamesNoMapCanHaveAreRefusedWithTheLine) {
  test::TempDir dir;
  const std::string msg = loadError(dir, "token-one-1 m\ntoken-two-2 bad%0Aname\n");
  EXPECT_NE(msg.find("tokens.txt:2"), std::string::npos) << msg;
  EXPECT_NE(msg.find("control character"), std::string::npos) << msg;
  EXPECT_NE(loadError(dir, "short m\n").find("shorter than 8"), std::string::npos);
}

}  // namespace
}  // namespace sglc::server
