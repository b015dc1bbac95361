// Registries in YAML and on the command line: nesting, application order, hostile text, dump and reload, the
// generated reference.
#include <gtest/gtest.h>

#include "sglc/config/settings_file.hpp"
#include "sglc/params.hpp"
#include "sglc/types.hpp"

namespace sglc::config {
namespace {

using namespace params;

struct Net {
  std::string listen = "127.0.0.1:1";
  int calls = 8;
  std::vector<std::uint32_t> ids{1};
};
struct Settings {
  Net net;
  double rate = 0.5;
  std::uint64_t seed = 3;
};

Table<Settings> table() {
  Table<Settings> t;
  t.add(field<Settings>(
      "net.listen", [](auto& s) -> auto& { return s.net.listen; }, {}, "address | port"));
  t.add(field<Settings>(
      "net.calls", [](auto& s) -> auto& { return s.net.calls; }, closed(1, 64), "calls"));
  t.add(field<Settings>(
      "net.ids", [](auto& s) -> auto& { return s.net.ids; }, {}, "ids"));
  t.add(field<Settings>(
      "rate", [](auto& s) -> auto& { return s.rate; }, above(0), "rate"));
  t.add(field<Settings>(
      "seed", [](auto& s) -> auto& { return s.seed; }, {}, "seed"));
  t.rule({"rate", "net.calls"}, "rate x calls <= 32", [](const Settings& s) { return s.rate * s.net.calls <= 32; });
  return t;
}

std::string errorOf(const std::string& yaml) {
  Settings s;
  try {
    applyYaml(table(), yaml, s);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(SettingsFile, NestedKeysAndDefaults) {
  Settings s;
  applyYaml(table(), "net:\n  calls: 16\n  ids: [4, 5]\nseed: 18446744073709551615\n", s);
  EXPECT_EQ(s.net.calls, 16);
  EXPECT_EQ(s.net.ids, (std::vector<std::uint32_t>{4, 5}));
  EXPECT_EQ(s.seed, 18446744073709551615ull);
  EXPECT_EQ(s.net.listen, "127.0.0.1:1");  // not given: default
  EXPECT_EQ(s.rate, 0.5);
  Settings empty;
  applyYaml(table(), "", empty);
  EXPECT_EQ(empty.net.calls, 8);
}

TEST(SettingsFile, MistakesAreNamed) {
  EXPECT_EQ(errorOf("nett:\n  calls: 1\n"), "config: unknown section 'nett' (known: net, rate, seed)");
  EXPECT_EQ(errorOf("net:\n  call: 1\n"), "config: unknown parameter 'net.call'");
  EXPECT_EQ(errorOf("net: 5\n"), "config: section 'net' must be a mapping");
  EXPECT_EQ(errorOf("net:\n  calls: 1\n  calls: 2\n"), "config: 'net.calls' is given twice");
  EXPECT_EQ(errorOf("net:\n  calls: 0\n"), "config: net.calls must be in [1, 64]");
  EXPECT_EQ(errorOf("net:\n  calls: 9999999999\n"),
            "config: net.calls must be an integer in [-2147483648, 2147483647]");
  EXPECT_NE(errorOf("net:\n  calls: 2.5\n").find("bad value for 'net.calls'"), std::string::npos);
  EXPECT_NE(errorOf("seed: -1\n").find("bad value for 'seed'"), std::string::npos);
  EXPECT_NE(errorOf("rate: .nan\n").find("rate must be > 0"), std::string::npos);
  EXPECT_NE(errorOf("net:\n  listen: [a]\n").find("net.listen must be text"), std::string::npos);
  EXPECT_NE(errorOf("net: {calls: 1").find("not valid YAML"), std::string::npos);
  EXPECT_EQ(errorOf("- a\n- b\n"), "config: the top level must be a mapping of sections");
  EXPECT_EQ(errorOf("? [a]\n: 1\n"), "config: the top level has a key that is not a plain name");
}

TEST(SettingsFile, CommandLineSetting) {
  Settings s;
  applySetting(table(), "net.ids=[7, 8]", s);
  applySetting(table(), "rate=2", s);
  EXPECT_EQ(s.net.ids, (std::vector<std::uint32_t>{7, 8}));
  EXPECT_EQ(s.rate, 2.0);
  auto error = [&](const std::string& text) {
    try {
      applySetting(table(), text, s);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_EQ(error("rate"), "config: 'rate' is not KEY=VALUE");
  EXPECT_EQ(error("rat=1"), "config: unknown parameter 'rat'");
  EXPECT_EQ(error("net=1"), "config: 'net' is a section, not a key (its keys: listen, calls, ids)");
  EXPECT_EQ(error("rate=-1"), "config: rate must be > 0");
  EXPECT_NE(error("net.calls=many").find("bad value for 'net.calls'"), std::string::npos);
  EXPECT_EQ(s.rate, 2.0);
}

TEST(SettingsFile, DumpReadsBackToTheSameValues) {
  Settings s;
  s.net.listen = "host: with # specials";
  s.rate = 0.1 + 0.2;
  s.net.ids = {};
  const auto yaml = dumpYaml(table(), s);
  Settings back;
  applyYaml(table(), yaml, back);
  EXPECT_EQ(back.net.listen, s.net.listen);
  EXPECT_EQ(back.rate, s.rate);
  EXPECT_TRUE(back.net.ids.empty());
  EXPECT_EQ(dumpYaml(table(), back), yaml);
}

TEST(SettingsFile, MarkdownListsEveryKeyWithDefaultRangeAndRules) {
  const auto md = markdownOf(table(), Settings{});
  EXPECT_NE(md.find("### `net`"), std::string::npos) << md;
  EXPECT_NE(md.find("| `calls` | `8` | integer in [1, 64] | calls |"), std::string::npos) << md;
  EXPECT_NE(md.find("| `listen` | `127.0.0.1:1` | text | address \\| port |"), std::string::npos) << md;
  EXPECT_NE(md.find("| `rate` | `0.5` | > 0 | rate |"), std::string::npos) << md;
  EXPECT_NE(md.find("- `rate` and `net.calls` must be rate x calls <= 32"), std::string::npos) << md;
}

TEST(SettingsFile, TextFilesAreBounded) {
  // A device that never ends is refused after 16 MiB instead of filling memory or hanging.
  try {
    readTextFile("/dev/zero");
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "/dev/zero: config file larger than 16 MiB");
  }
  try {
    readTextFile("/nonexistent/x.pem", "TLS key");
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "/nonexistent/x.pem: cannot open TLS key");
  }
}

}  // namespace
}  // namespace sglc::config
