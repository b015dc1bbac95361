// The fingerprint-shaping settings: which keys they are, their hash, and the first difference between two sets.
#include <gtest/gtest.h>

#include "sglc/fingerprint_settings.hpp"

namespace sglc {
namespace {

Config with(const std::string& key, const params::Value& value) {
  Config c;
  engineParams().assign(c, key, value);
  engineParams().finishAssignment(c);
  return c;
}

TEST(FingerprintSettings, ListsEveryShapingKeyOfTheRegistryAndNoOther) {
  const auto s = fingerprintSettings(Config{});
  std::size_t shaping = 0;
  for (const auto& p : engineParams().params()) shaping += shapesFingerprints(p.info.key) ? 1 : 0;
  ASSERT_EQ(s.values.size(), shaping);
  EXPECT_GT(shaping, 40U);
  for (const auto& [key, value] : s.values) {
    const auto section = key.substr(0, key.find('.'));
    EXPECT_TRUE(section == "labels" || section == "labeller" || section == "cluster" || section == "graph" ||
                section == "descriptor" || section == "fingerprint")
        << key;
  }
  EXPECT_EQ(s.values.front(), (Setting{"labels.preset", "semantickitti"}));
  for (const char* key :
       {"verify.min_probability", "match.max_distance_m", "ransac.seed", "refine.max_iterations", "path"})
    EXPECT_FALSE(shapesFingerprints(key)) << key;
  EXPECT_FALSE(shapesFingerprints("labelsx.preset"));
  EXPECT_FALSE(shapesFingerprints("labels"));
}

TEST(FingerprintSettings, HashIsStableAndFollowsTheValues) {
  const auto a = fingerprintSettings(Config{});
  EXPECT_EQ(a.hash, fingerprintSettings(Config{}).hash);
  EXPECT_EQ(a.hash.size(), 16U);
  EXPECT_EQ(a.hash, settingsHash(a.values));
  // FNV-1a 64 of nothing is its offset basis; one key and value, computed by hand.
  EXPECT_EQ(settingsHash({}), "cbf29ce484222325");
  EXPECT_NE(settingsHash({{"a", "bc"}}), settingsHash({{"ab", "c"}}));
  EXPECT_NE(settingsHash({{"a", "b"}, {"c", "d"}}), settingsHash({{"c", "d"}, {"a", "b"}}));
}

TEST(FingerprintSettings, AShapingChangeChangesTheHashAndIsNamed) {
  const auto base = fingerprintSettings(Config{});
  const struct {
    const char* key;
    params::Value value;
    const char* expect_value;
  } cases[] = {{"labels.preset", std::string("nuscenes"), "nuscenes"},
               {"labeller.mode", std::string("always"), "always"},
               {"labeller.cell_m", 0.3, "0.3"},
               {"cluster.range_m", 1.5, "1.5"},
               {"descriptor.rings", std::int64_t{6}, "6"}};
  for (const auto& c : cases) {
    const auto other = fingerprintSettings(with(c.key, c.value));
    EXPECT_NE(other.hash, base.hash) << c.key;
    const auto d = firstDifference(base, other);
    ASSERT_TRUE(d) << c.key;
    EXPECT_EQ(d->key, c.key);
    EXPECT_EQ(d->current, c.expect_value);
    EXPECT_EQ(d->recorded, params::format(engineParams().find(c.key)->get(Config{})));
  }
}

TEST(FingerprintSettings, VerificationSettingsDoNotCount) {
  const auto base = fingerprintSettings(Config{});
  for (const auto& [key, value] :
       std::vector<std::pair<std::string, params::Value>>{{"verify.min_probability", 0.7},
                                                          {"ransac.seed", std::uint64_t{7}},
                                                          {"refine.max_iterations", std::int64_t{3}}}) {
    const auto other = fingerprintSettings(with(key, value));
    EXPECT_EQ(other, base) << key;
    EXPECT_FALSE(firstDifference(base, other)) << key;
  }
}

TEST(FingerprintSettings, TheFirstDifferenceIsTheFirstKeyInRegistryOrder) {
  auto c = with("labeller.cell_m", 0.3);
  engineParams().assign(c, "labels.preset", std::string("nuscenes"));
  const auto d = firstDifference(fingerprintSettings(Config{}), fingerprintSettings(c));
  ASSERT_TRUE(d);
  EXPECT_EQ(d->key, "labels.preset");
  EXPECT_EQ(d->recorded, "semantickitti");
  EXPECT_EQ(d->current, "nuscenes");
}

TEST(FingerprintSettings, KeysTheRecordLacksAgreeAtTheirDefault) {
  const auto current = fingerprintSettings(Config{});
  auto older = current;  // a map recorded by a build without labeller.cell_m
  std::erase_if(older.values, [](const Setting& s) { return s.first == "labeller.cell_m"; });
  older.values.emplace_back("labeller.retired_knob", "3");  // and with a setting this build no longer has
  EXPECT_FALSE(firstDifference(older, current));
  const auto d = firstDifference(older, fingerprintSettings(with("labeller.cell_m", 0.3)));
  ASSERT_TRUE(d);
  EXPECT_EQ(d->key, "labeller.cell_m");
  EXPECT_EQ(d->recorded, "(not recorded)");
  EXPECT_EQ(d->current, "0.3");
}

}  // namespace
}  // namespace sglc
