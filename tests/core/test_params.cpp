// The settings registry: ranges, kinds, assignment by key, validation with rules, nesting under a section.
#include <gtest/gtest.h>

#include <chrono>

#include "sglc/config.hpp"
#include "sglc/params.hpp"
#include "sglc/types.hpp"

namespace sglc::params {
namespace {

struct Inner {
  double gain = 1.5;
  int count = 4;
  std::string mode = "fast";
  enum class Sync { kOff, kFull } sync = Sync::kFull;
  std::chrono::milliseconds wait{2500};
};
struct Outer {
  Inner inner;
  bool on = true;
};

Table<Inner> innerTable() {
  Table<Inner> t;
  t.add(field<Inner>(
      "gain", [](auto& s) -> auto& { return s.gain; }, openClosed(0, 10), "gain"));
  t.add(field<Inner>(
      "count", [](auto& s) -> auto& { return s.count; }, closed(1, 100), "count"));
  t.add(field<Inner>("mode", [](auto& s) -> auto& { return s.mode; }, {}, "mode", {"fast", "slow"}));
  t.add(choice<Inner>(
      "sync", [](auto& s) -> auto& { return s.sync; },
      std::vector<std::pair<std::string, Inner::Sync>>{{"off", Inner::Sync::kOff}, {"full", Inner::Sync::kFull}},
      "sync"));
  t.add(duration<Inner>(
      "wait_s", [](auto& s) -> auto& { return s.wait; }, 1000, atLeast(0.1), "wait"));
  t.rule({"gain", "count"}, "gain x count <= 100", [](const Inner& s) { return s.gain * s.count <= 100; });
  return t;
}

std::string errorOf(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(Params, RangeTextAndMembership) {
  EXPECT_EQ(openClosed(0, 90).text(), "in (0, 90]");
  EXPECT_EQ(closed(-1, 1).text(), "in [-1, 1]");
  EXPECT_EQ(above(0).text(), "> 0");
  EXPECT_EQ(atLeast(0.05).text(), ">= 0.05");
  EXPECT_EQ(finite().text(), "finite");
  EXPECT_FALSE(openClosed(0, 90).contains(0));
  EXPECT_TRUE(openClosed(0, 90).contains(90));
  EXPECT_FALSE(finite().contains(std::numeric_limits<double>::quiet_NaN()));
  EXPECT_FALSE(atLeast(0).contains(std::numeric_limits<double>::infinity()));
}

TEST(Params, FormatIsShortestExact) {
  EXPECT_EQ(format(Value(0.45)), "0.45");
  EXPECT_EQ(format(Value(0.1 + 0.2)), "0.30000000000000004");
  EXPECT_EQ(format(Value(1e6)), "1000000");
  EXPECT_EQ(format(Value(std::vector<std::uint32_t>{40, 44})), "[40, 44]");
  EXPECT_EQ(format(Value(true)), "true");
}

TEST(Params, AssignChecksBeforeWriting) {
  const auto t = innerTable();
  Inner s;
  t.assign(s, "gain", 2.5);
  EXPECT_EQ(s.gain, 2.5);
  EXPECT_EQ(errorOf([&] { t.assign(s, "gain", 0.0); }), "config: gain must be in (0, 10]");
  EXPECT_EQ(s.gain, 2.5);  // a refused value leaves the field as it was
  // An integer beyond int: refused, not wrapped.
  EXPECT_NE(errorOf([&] { t.assign(s, "count", std::int64_t{1} << 40); }).find("count must be an integer"),
            std::string::npos);
  EXPECT_EQ(s.count, 4);
  EXPECT_EQ(errorOf([&] { t.assign(s, "mode", std::string("medium")); }),
            "config: mode must be fast or slow (not 'medium')");
  EXPECT_NE(errorOf([&] { t.assign(s, "gain", std::string("2")); }).find("gain must be a value of kind number"),
            std::string::npos);
  EXPECT_EQ(errorOf([&] { t.assign(s, "gian", 1.0); }), "config: unknown parameter 'gian'");
  t.assign(s, "sync", std::string("off"));
  EXPECT_EQ(s.sync, Inner::Sync::kOff);
  EXPECT_EQ(std::get<std::string>(t.find("sync")->get(s)), "off");
  // A duration cannot be set beyond what its milliseconds hold, whatever range it was declared with.
  EXPECT_NE(errorOf([&] { t.assign(s, "wait_s", 1e300); }).find("wait_s must be in [0.1, "), std::string::npos);
  t.assign(s, "wait_s", 0.25);
  EXPECT_EQ(s.wait.count(), 250);
  EXPECT_EQ(std::get<double>(t.find("wait_s")->get(s)), 0.25);
}

TEST(Params, ValidateChecksRangesThenRules) {
  const auto t = innerTable();
  Inner s;
  EXPECT_NO_THROW(t.validate(s));
  s.count = 0;
  EXPECT_EQ(errorOf([&] { t.validate(s); }), "config: count must be in [1, 100]");
  s.count = 80;
  EXPECT_EQ(errorOf([&] { t.validate(s); }), "config: gain and count must be gain x count <= 100");
}

TEST(Params, NestedTablePrefixesKeysAndRules) {
  Table<Outer> outer;
  innerTable().nestInto(
      outer, "inner", [](auto& o) -> auto& { return o.inner; });
  outer.add(field<Outer>(
      "on", [](auto& o) -> auto& { return o.on; }, {}, "on"));
  ASSERT_NE(outer.find("inner.gain"), nullptr);
  EXPECT_EQ(outer.find("gain"), nullptr);
  Outer o;
  outer.assign(o, "inner.count", std::int64_t{7});
  outer.assign(o, "on", false);
  EXPECT_EQ(o.inner.count, 7);
  EXPECT_FALSE(o.on);
  o.inner.gain = 20;
  EXPECT_EQ(errorOf([&] { outer.validate(o); }), "config: inner.gain must be in (0, 10]");
  o.inner.gain = 10;
  o.inner.count = 11;
  EXPECT_EQ(errorOf([&] { outer.validate(o); }), "config: inner.gain and inner.count must be gain x count <= 100");
}

// The engine's table covers every key once, and its defaults are valid.
TEST(Params, EngineTableKeysAreUniqueAndDefaultsValid) {
  const auto& t = engineParams();
  std::set<std::string> keys;
  for (const auto& p : t.params()) {
    EXPECT_TRUE(keys.insert(p.info.key).second) << p.info.key << " declared twice";
    EXPECT_FALSE(p.info.doc.empty()) << p.info.key << " has no documentation";
    EXPECT_NE(p.info.key.find('.'), std::string::npos) << p.info.key << " has no section";
  }
  EXPECT_GE(keys.size(), 89u);
  EXPECT_NO_THROW(t.validate(Config{}));
}

TEST(Params, EngineTableReadsAndWritesTheStruct) {
  const auto& t = engineParams();
  Config c;
  t.assign(c, "verify.min_probability", 0.4);
  t.assign(c, "ransac.seed", std::uint64_t{7});
  t.assign(c, "labels.road", std::vector<std::uint32_t>{1, 2});
  EXPECT_EQ(c.verify.min_probability, 0.4);
  EXPECT_EQ(c.ransac.seed, 7u);
  EXPECT_EQ(c.labels.road, (std::vector<std::uint32_t>{1, 2}));
  EXPECT_EQ(std::get<double>(t.find("verify.min_probability")->get(c)), 0.4);
  // A preset replaces every list; lists edited afterwards make the labels "custom".
  t.assign(c, "labels.preset", std::string("nuscenes"));
  EXPECT_EQ(c.labels.road, (std::vector<std::uint32_t>{24}));
  t.finishAssignment(c);
  EXPECT_EQ(c.labels.preset, "nuscenes");
  t.assign(c, "labels.fence", std::vector<std::uint32_t>{9, 10});
  t.finishAssignment(c);
  EXPECT_EQ(c.labels.preset, "custom");
}

}  // namespace
}  // namespace sglc::params
