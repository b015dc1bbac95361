// Each map's fingerprint settings in the map database, on both back-ends: recorded when the map is created, read
// back across reopening, given once to maps that have none (maps from before they were recorded), deleted with
// the map, and refused when damaged.
#include <sqlite3.h>

#include <future>

#include "backend.hpp"
#include "storage_test_util.hpp"

namespace sglc::storage {
namespace {

using testing::errorCode;

FingerprintSettings settingsWith(const std::string& key, const params::Value& value) {
  Config c;
  engineParams().assign(c, key, value);
  engineParams().finishAssignment(c);
  return fingerprintSettings(c);
}

const FingerprintSettings kDefaults = fingerprintSettings(Config{});
const FingerprintSettings kNuscenes = settingsWith("labels.preset", std::string("nuscenes"));

class MapSettingsStore : public testing::OnBothBackends {
 protected:
  std::unique_ptr<MapStore> open(const FingerprintSettings& settings) {
    auto o = db().options();
    o.settings = settings;
    return MapStore::open(o);
  }
  // SQL on the database behind the store's back (the store is closed).
  void exec(const std::string& sql) {
    const auto path = db().options().path;
    if (db().postgres()) return pg::Conn(path).exec(sql);
    sqlite3* h = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &h), SQLITE_OK);
    EXPECT_EQ(sqlite3_exec(h, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(h);
    sqlite3_close(h);
  }
  static constexpr int kDim = 64;
};

TEST_P(MapSettingsStore, RecordsTheCreatorsSettingsAndReadsThemBack) {
  ASSERT_NE(kDefaults.hash, kNuscenes.hash);
  {
    auto store = open(kDefaults);
    store->createMap("m", kDim);
    EXPECT_EQ(store->mapSettings("m"), kDefaults);
    EXPECT_EQ(errorCode([&] { store->mapSettings("nope"); }), StorageError::Code::kNotFound);
    EXPECT_EQ(errorCode([&] { store->recordSettings("nope"); }), StorageError::Code::kNotFound);
    EXPECT_TRUE(store->recordSettings().empty());  // it has them
  }
  auto store = open(kNuscenes);  // a server with other settings: the map keeps its own
  EXPECT_EQ(store->mapSettings("m"), kDefaults);
  EXPECT_TRUE(store->recordSettings().empty());
  store->createMap("m", kDim);  // idempotent: changes nothing
  EXPECT_EQ(store->mapSettings("m"), kDefaults);
  store->createMap("n", kDim);
  EXPECT_EQ(store->mapSettings("n"), kNuscenes);
}

TEST_P(MapSettingsStore, AMapWithoutSettingsGetsThoseOfTheFirstStoreThatRecords) {
  {
    auto store = open({});  // a store that records nothing
    store->createMap("a", kDim);
    store->createMap("b", kDim);
    EXPECT_EQ(store->mapSettings("a"), std::nullopt);
    EXPECT_TRUE(store->recordSettings().empty());
  }
  {
    auto first = open(kNuscenes);
    EXPECT_EQ(first->mapSettings("b"), std::nullopt);
    EXPECT_EQ(first->recordSettings("b"), std::vector<std::string>{"b"});
    EXPECT_EQ(first->mapSettings("a"), std::nullopt);  // only the map named
  }
  {
    auto second = open(kDefaults);
    EXPECT_EQ(second->recordSettings(), std::vector<std::string>{"a"});
    EXPECT_EQ(second->recordSettings(), std::vector<std::string>{});  // once
  }
  auto store = open(kNuscenes);
  EXPECT_EQ(store->recordSettings(), std::vector<std::string>{});
  EXPECT_EQ(store->mapSettings("a"), kDefaults);
  EXPECT_EQ(store->mapSettings("b"), kNuscenes);
}

// Replicas on one PostgreSQL database: a map without settings, recorded by two at once, gets one's.
TEST_P(MapSettingsStore, ReplicasRecordAMapOnce) {
  if (!db().postgres()) GTEST_SKIP() << "one store at a time opens a SQLite file";
  open({})->createMap("m", kDim);
  auto a = open(kDefaults);
  auto b = open(kNuscenes);
  auto from_a = std::async(std::launch::async, [&] { return a->recordSettings(); });
  const auto got_b = b->recordSettings();
  const auto got_a = from_a.get();
  EXPECT_EQ(got_a.size() + got_b.size(), 1U);
  const auto& winner = got_a.empty() ? kNuscenes : kDefaults;
  EXPECT_EQ(a->mapSettings("m"), winner);
  EXPECT_EQ(b->mapSettings("m"), winner);
}

TEST_P(MapSettingsStore, TheSettingsGoWithTheMap) {
  auto store = open(kDefaults);
  store->createMap("m", kDim);
  store->deleteMap("m");
  store.reset();
  store = open(kNuscenes);
  EXPECT_EQ(errorCode([&] { store->mapSettings("m"); }), StorageError::Code::kNotFound);
  store->createMap("m", kDim);  // a new map under the old name: this store's settings
  EXPECT_EQ(store->mapSettings("m"), kNuscenes);
}

// A database from before settings were recorded (SQLite schema 6, PostgreSQL schema 2): opening migrates it, its
// maps have none until a store records its own.
TEST_P(MapSettingsStore, MigrationLeavesOlderMapsForTheFirstRecorder) {
  {
    auto store = open(kDefaults);
    const auto fp = testing::randomFingerprint(3);
    store->createMap("old", static_cast<int>(fp.descriptor.size()));
    store->addScan({.map = "old", .robot = "r", .session = "s", .seq = 0, .fingerprint = &fp});
  }
  // Schema 6 (PostgreSQL 2) had neither the settings nor the loops' probability (schema 8 / 4).
  exec(db().postgres() ? "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN "
                         "retired_bytes; DROP TABLE map_settings; ALTER TABLE maps DROP COLUMN settings_hash;"
                         " ALTER TABLE loops DROP COLUMN probability;"
                         " UPDATE sglc_meta SET value = '2' WHERE key = 'schema_version'"
                       : "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN "
                         "retired_bytes; DROP TABLE map_settings; ALTER TABLE maps DROP COLUMN settings_hash;"
                         " ALTER TABLE loops DROP COLUMN probability; PRAGMA user_version=6;");
  auto store = open(kNuscenes);
  EXPECT_EQ(store->mapSettings("old"), std::nullopt);
  EXPECT_EQ(store->recordSettings(), std::vector<std::string>{"old"});
  EXPECT_EQ(store->mapSettings("old"), kNuscenes);
  EXPECT_EQ(store->stats("old").scans, 1);
  store.reset();
  store = open(kDefaults);  // recorded for good
  EXPECT_EQ(store->mapSettings("old"), kNuscenes);
}

TEST_P(MapSettingsStore, DamagedSettingsAreCorrupt) {
  open(kDefaults)->createMap("m", kDim);
  exec("UPDATE map_settings SET value = 'nuscenes' WHERE key = 'labels.preset'");
  auto store = open(kDefaults);
  EXPECT_EQ(errorCode([&] { store->mapSettings("m"); }), StorageError::Code::kCorrupt);
}

INSTANTIATE_TEST_SUITE_P(MapSettings, MapSettingsStore, ::testing::Values("sqlite", "postgresql"),
                         [](const ::testing::TestParamInfo<std::string>& info) { return info.param; });

}  // namespace
}  // namespace sglc::storage
