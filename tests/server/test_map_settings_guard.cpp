// The server's check that a map's fingerprints and its own are made alike: the refusal's code and message, maps
// without settings getting the server's, and a map deleted and created again judged afresh.
#include <gtest/gtest.h>

#include "map_settings_guard.hpp"
#include "rpc_error.hpp"
#include "settings.hpp"
#include "test_util.hpp"

namespace sglc::server {
namespace {

FingerprintSettings settingsWith(const std::string& key, const params::Value& value) {
  Config c;
  engineParams().assign(c, key, value);
  engineParams().finishAssignment(c);
  return fingerprintSettings(c);
}

std::unique_ptr<storage::MapStore> openStore(const test::TempDir& dir, const FingerprintSettings& settings) {
  storage::StoreOptions o;
  o.path = dir.file("map.db");
  o.sync = storage::StoreOptions::Sync::kNormal;
  o.snapshot_index = false;
  o.settings = settings;
  return storage::MapStore::open(o);
}

// The status code and message require() throws ("OK" when it does not).
std::pair<std::string, std::string> verdictOf(const MapSettingsGuard& guard, storage::MapStore& store,
                                              const std::string& map) {
  try {
    guard.require(store, map);
  } catch (const RpcError& e) {
    return {e.code() == grpc::StatusCode::FAILED_PRECONDITION ? "FAILED_PRECONDITION"
            : e.code() == grpc::StatusCode::NOT_FOUND         ? "NOT_FOUND"
                                                              : "other",
            e.what()};
  }
  return {"OK", ""};
}

const FingerprintSettings kDefaults = fingerprintSettings(Config{});
const FingerprintSettings kNuscenes = settingsWith("labels.preset", std::string("nuscenes"));

TEST(MapSettingsGuard, RefusesAMapOfOtherSettingsNamingTheKeyAndBothValues) {
  test::TempDir dir;
  openStore(dir, kDefaults)->createMap("m", 64);
  auto store = openStore(dir, kNuscenes);
  const MapSettingsGuard guard(kNuscenes);
  const auto [code, message] = verdictOf(guard, *store, "m");
  EXPECT_EQ(code, "FAILED_PRECONDITION");
  EXPECT_EQ(message.rfind("map 'm' was built with labels.preset = semantickitti; this server has nuscenes: ", 0), 0U)
      << message;
  EXPECT_EQ(verdictOf(guard, *store, "m").first, "FAILED_PRECONDITION");  // the cached verdict
  EXPECT_EQ(verdictOf(guard, *store, "nope").first, "NOT_FOUND");
  store->createMap("n", 64);  // this server's own map
  EXPECT_EQ(verdictOf(guard, *store, "n").first, "OK");
  // A server with the map's settings, verification settings apart, may use it.
  EXPECT_EQ(verdictOf(MapSettingsGuard(kDefaults), *store, "m").first, "OK");
  EXPECT_EQ(verdictOf(MapSettingsGuard(settingsWith("verify.min_probability", 0.7)), *store, "m").first, "OK");
}

TEST(MapSettingsGuard, AMapWithoutSettingsGetsThisServersOnFirstUse) {
  test::TempDir dir;
  openStore(dir, {})->createMap("m", 64);  // as an older build made it
  auto store = openStore(dir, kNuscenes);
  EXPECT_EQ(store->mapSettings("m"), std::nullopt);
  EXPECT_EQ(verdictOf(MapSettingsGuard(kNuscenes), *store, "m").first, "OK");
  EXPECT_EQ(store->mapSettings("m"), kNuscenes);
  EXPECT_EQ(verdictOf(MapSettingsGuard(kDefaults), *store, "m").first, "FAILED_PRECONDITION");
}

TEST(MapSettingsGuard, AMapCreatedAgainIsJudgedAgain) {
  test::TempDir dir;
  auto store = openStore(dir, kDefaults);
  store->createMap("m", 64);
  const MapSettingsGuard guard(kDefaults);
  EXPECT_EQ(verdictOf(guard, *store, "m").first, "OK");
  store->deleteMap("m");
  store.reset();
  store = openStore(dir, kNuscenes);
  store->createMap("m", 64);  // a new map (a new id) of other settings
  EXPECT_EQ(verdictOf(guard, *store, "m").first, "FAILED_PRECONDITION");
}

TEST(MapSettingsGuard, LongValuesAreShortenedInTheMessage) {
  const auto message =
      settingsMismatchMessage("m", {"labels.node_classes", std::string(500, 'a'), std::string(300, 'b')});
  EXPECT_LT(message.size(), 600U);
  EXPECT_NE(message.find("labels.node_classes = " + std::string(120, 'a') + "...; this server has "),
            std::string::npos);
}

}  // namespace
}  // namespace sglc::server
