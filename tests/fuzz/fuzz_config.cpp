// Fuzzing sglc::parseConfig (engine configuration YAML, e.g. the server's --config file): it returns a valid
// Config or throws InputError. An accepted text must give a configuration that validates and survives
// dumpConfig -> parseConfig unchanged (engine_file.hpp: "YAML that parseConfig reads back to the same values").
#include "fuzz_util.hpp"
#include "sglc/config/engine_file.hpp"
#include "sglc/types.hpp"

namespace sglc {
namespace {

using fuzz::Outcome;
using fuzz::Rng;

std::vector<std::string> seedTexts() {
  return {
      dumpConfig(Config{}),
      "",
      "{}\n",
      "cluster:\n  min_points: 5\n  azimuth_deg: 1.5\n  max_range_m: 70\n",
      "labels:\n  node_classes:\n    - {name: car, ids: [10, 18]}\n    - name: pole\n      ids: [80, 81]\n"
      "  road: [40, 44]\n  moving: []\n",
      "graph: {d_max: 30, max_nodes: 50}\ndescriptor: {d_i: 1.0, k_eigen: 10, rings: 12}\n",
      "fine:\n  enabled: false\nrefine:\n  enabled: true\n  cauchy_m: 0.2\nbev_search: {keep: 2, cell_m: 0.5}\n",
      "ransac:\n  seed: 18446744073709551615\n  max_iterations: 100\n# a comment\nverify: {t_g: 0.4, t_b: 0.5}\n",
      // Regression inputs found by this test: mapping keys that are not scalars, at the top level and inside a
      // section. parseConfig converts keys with as<std::string>() outside its try blocks, so
      // YAML::TypedBadConversion<std::string> escaped instead of InputError.
      "{}: {}\n",
      "cluster:\n  ? [min_points]\n  : 5\n",
  };
}

// YAML syntax and values at and beyond the edges of the registry's ranges.
std::vector<std::string> syntaxAndValues() {
  return {":",
          ": ",
          "- ",
          "-",
          "{",
          "}",
          "[",
          "]",
          ",",
          "? ",
          "&a ",
          "*a",
          "<<: *a\n",
          "!!str ",
          "!!int ",
          "!!map ",
          "!!seq ",
          "!!binary ",
          "!<tag:yaml.org,2002:str> ",
          "%YAML 1.2\n---\n",
          "---\n",
          "...\n",
          "|\n",
          ">\n",
          "'",
          "\"",
          "\\",
          "#",
          "\n",
          "  ",
          "    ",
          "\t",
          "~",
          "null",
          "true",
          "false",
          "yes",
          "0",
          "-0",
          "1",
          "-1",
          "3",
          "1000",
          "2000",
          "2147483647",
          "2147483648",
          "-2147483649",
          "4294967295",
          "4294967296",
          "18446744073709551615",
          "18446744073709551616",
          "0x7fffffff",
          "0o777",
          "1e308",
          "1e309",
          "-1e309",
          ".nan",
          ".inf",
          "-.inf",
          ".NaN",
          "1e-320",
          "0.5",
          "1.0e+2",
          "nan",
          "inf",
          "\xef\xbb\xbf",
          "\xff",
          "\"\\u0000\"",
          "\"\\x80\"",
          "{name: a, ids: [1]}",
          "[1, 2, 3]",
          "{}",
          "[]"};
}

// Section and key names: every key of the engine's registry, split at its dots, and the node-class fields.
std::vector<std::string> dictionary() {
  std::vector<std::string> d = syntaxAndValues();
  std::set<std::string> names;
  for (const auto& p : engineParams().params()) {
    const auto& key = p.info.key;
    names.insert(key.substr(0, key.find('.')));
    names.insert(key.substr(key.find('.') + 1));
  }
  d.insert(d.end(), names.begin(), names.end());
  d.emplace_back("name");
  d.emplace_back("ids");
  d.emplace_back(std::string("\0", 1));
  return d;
}

TEST(Fuzz, ConfigParse) {
  const std::vector<std::string> corpus = seedTexts();
  const fuzz::Mutator mutator(dictionary(), /*text=*/true);
  constexpr std::size_t kMaxSize = 16 * 1024;
  auto make = [&](Rng& rng, std::uint64_t i) -> std::string {
    if (i < corpus.size()) return corpus[i];
    if (fuzz::chance(rng, 10)) return mutator.random(rng, 2048);
    std::string text = corpus[fuzz::below(rng, corpus.size())];
    mutator.mutate(rng, text, corpus, kMaxSize);
    return text;
  };
  auto check = [&](const std::string& text, fuzz::Verdict& v) -> Outcome {
    Config config;
    try {
      config = parseConfig(text);
    } catch (const InputError& e) {
      if (!*e.what()) v.fail("InputError with an empty message");
      return Outcome::kRejected;
    }
    try {
      validateConfig(config);
    } catch (const InputError& e) {
      v.fail(std::string("accepted config fails validateConfig: ") + e.what());
    }
    const std::string dumped = dumpConfig(config);
    try {
      const std::string again = dumpConfig(parseConfig(dumped));
      if (again != dumped)
        v.fail("dumpConfig -> parseConfig -> dumpConfig changes the configuration:\n" +
               fuzz::textPreview(dumped, 4000) + "\n  becomes\n" + fuzz::textPreview(again, 4000));
    } catch (const InputError& e) {
      v.fail(std::string("parseConfig rejects dumpConfig's output of an accepted config: ") + e.what() + "\n" +
             fuzz::textPreview(dumped, 4000));
    }
    return Outcome::kAccepted;
  };
  const auto r = fuzz::runFuzzBytes("ConfigParse", 50000, corpus.size(), make, check, /*text=*/true);
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, 8u) << "the 8 valid seeds must parse";
    EXPECT_GT(r.rejected, 0u);
  }
}

}  // namespace
}  // namespace sglc
