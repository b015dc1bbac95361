// The server's settings: one registry over four sections, the order in which sources apply, the example file.
#include <gtest/gtest.h>

#include <fstream>
#include <set>

#include "settings.hpp"
#include "sglc/config/settings_file.hpp"
#include "sglc/types.hpp"
#include "test_util.hpp"

namespace sglc::server {
namespace {

std::string errorOf(const std::string& path, const std::vector<std::pair<std::string, std::string>>& overrides) {
  try {
    settingsFrom(path, overrides);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(ServerSettings, OneRegistryOverFiveSections) {
  std::set<std::string> sections, keys;
  for (const auto& p : settingsTable().params()) {
    sections.insert(p.info.key.substr(0, p.info.key.find('.')));
    EXPECT_TRUE(keys.insert(p.info.key).second) << p.info.key;
  }
  EXPECT_EQ(sections, (std::set<std::string>{"engine", "map", "pose_graph", "server", "storage"}));
  for (const auto* key : {"server.max_calls", "storage.sync", "pose_graph.debounce_ms", "engine.verify.min_probability",
                          "engine.refine.max_shift_m", "engine.labels.preset", "map.max_versions_per_place"})
    EXPECT_TRUE(keys.count(key)) << key;
  EXPECT_NO_THROW(settingsTable().validate(Settings{}));
}

TEST(ServerSettings, FileThenOverridesInOrder) {
  test::TempDir dir;
  const auto path = dir.file("s.yaml");
  std::ofstream(path)
      << "server: {max_calls: 64, threads: 3}\nstorage: {sync: off}\n"
         "pose_graph: {debounce_ms: 50}\nengine: {verify: {min_probability: 0.3}, labels: {preset: nuscenes}}\n";
  const auto s = settingsFrom(path, {{"--set", "server.max_calls=32"}, {"--max-calls 16", "server.max_calls=16"}});
  EXPECT_EQ(s.max_calls, 16);  // the last override wins
  EXPECT_EQ(s.threads, 3);     // from the file
  EXPECT_EQ(s.store.sync, storage::StoreOptions::Sync::kOff);
  EXPECT_EQ(s.graph.debounce.count(), 50);
  EXPECT_EQ(s.engine.verify.min_probability, 0.3);
  EXPECT_EQ(s.engine.labels.road, (std::vector<std::uint32_t>{24}));  // the preset's lists
  EXPECT_EQ(s.engine.labels.preset, "nuscenes");
  // Text from the command line is taken as given (a path may hold '#' or ': ').
  EXPECT_EQ(settingsFrom("", {{"--db", "server.db=maps/a #1: b.db"}}).db, "maps/a #1: b.db");
}

TEST(ServerSettings, ErrorsNameTheSourceAndTheKey) {
  test::TempDir dir;
  const auto path = dir.file("bad.yaml");
  std::ofstream(path) << "pose_graph: {loss_scale: -1}\n";
  EXPECT_EQ(errorOf(path, {}), path + ": config: pose_graph.loss_scale must be > 0");
  EXPECT_EQ(errorOf("", {{"--max-calls 0", "server.max_calls=0"}}),
            "--max-calls 0: config: server.max_calls must be in [1, 4096]");
  // Rules are checked once every source has applied: either order of the two keys gives the error.
  EXPECT_EQ(errorOf("", {{"a", "server.tls_cert=c.pem"}}),
            "config: server.tls_cert and server.tls_key must be given together");
  EXPECT_EQ(errorOf("", {{"a", "server.tls_cert=c.pem"}, {"b", "server.tls_key=k.pem"}}), "(no error)");
  EXPECT_EQ(errorOf("", {{"a", "pose_graph.odometry_sigma_m=0"}, {"b", "pose_graph.odometry_sigma_per_m=0"}}),
            "config: pose_graph.odometry_sigma_m and pose_graph.odometry_sigma_per_m must be > 0 in sum");
  EXPECT_NE(errorOf(dir.file("missing.yaml"), {}).find("missing.yaml: cannot open"), std::string::npos);
  // Values that would overflow the integer they are converted to (milliseconds, bytes, pages) are refused.
  EXPECT_EQ(errorOf("", {{"a", "server.stream_idle_timeout_s=1e300"}}),
            "a: config: server.stream_idle_timeout_s must be in [0.1, 86400]");
  EXPECT_EQ(errorOf("", {{"a", "storage.cache_mb=1e300"}}), "a: config: storage.cache_mb must be in [0, 1000000000]");
  EXPECT_EQ(errorOf("", {{"a", "storage.max_db_mb=1e300"}}), "a: config: storage.max_db_mb must be in [0, 1000000000]");
}

TEST(ServerSettings, DumpReadsBackAndTheExampleFileIsValid) {
  test::TempDir dir;
  Settings s = settingsFrom(std::string(SGLC_SOURCE_DIR) + "/deploy/sglc.yaml", {});
  EXPECT_EQ(s.listen, "127.0.0.1:50051");
  s.max_inflight_mb = 0.1 + 1000;
  s.streams.idle_timeout = std::chrono::milliseconds(1500);
  const auto yaml = config::dumpYaml(settingsTable(), s);
  std::ofstream(dir.file("dump.yaml")) << yaml;
  const auto back = settingsFrom(dir.file("dump.yaml"), {});
  EXPECT_EQ(config::dumpYaml(settingsTable(), back), yaml);
  EXPECT_EQ(back.max_inflight_mb, s.max_inflight_mb);
  EXPECT_EQ(back.streams.idle_timeout.count(), 1500);
}

TEST(ServerSettings, ResolvedFillsTheDerivedValues) {
  Settings s;
  s.db = "/srv/maps/fleet.db";
  const auto r = resolved(s);
  EXPECT_GE(r.threads, 1);
  EXPECT_EQ(r.backup_dir, "/srv/maps/backups");
  EXPECT_EQ(r.store.path, s.db);
  const auto limits = limitsOf(r);
  EXPECT_EQ(limits.max_message_bytes, 64 << 20);
  EXPECT_EQ(limits.streams.max_total, 1024);
}

}  // namespace
}  // namespace sglc::server
