// The loop model's probability on stored loops: round trips on both back-ends, the refusal of values outside
// [0, 1] (NaN included), and the migration that adds the column, under which older loops read as unknown.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cmath>
#include <limits>

#include "backend.hpp"
#include "postgres.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::storage {
namespace {

using testing::Backend;
using testing::errorCode;
using testing::randomFingerprint;

// Map "m" with `n` scans of one session; their ids.
std::vector<std::int64_t> scans(MapStore& store, int n) {
  store.createMap("m", DescriptorLayout{}.scanDim());
  std::vector<std::int64_t> ids;
  for (int k = 0; k < n; ++k) {
    const auto fp = randomFingerprint(100 + k);
    ids.push_back(store.addScan({.map = "m", .robot = "r", .session = "s", .seq = k, .fingerprint = &fp}));
  }
  return ids;
}

class LoopProbabilityOnBothBackends : public testing::OnBothBackends {};

LoopRecord loop(std::int64_t query, std::int64_t candidate, std::optional<double> probability) {
  LoopRecord r{0, query, candidate, Mat4d::Identity(), 0.5, 0.6, 0.1, 7};
  r.probability = probability;
  return r;
}

TEST_P(LoopProbabilityOnBothBackends, LoopProbabilityRoundTripsAndUnknownStaysUnknown) {
  {
    auto store = db().open();
    const auto ids = scans(*store, 4);
    store->addLoop("m", loop(ids[3], ids[0], 0.8125));
    store->addLoop("m", loop(ids[3], ids[1], std::nullopt));
    store->addLoop("m", loop(ids[2], ids[0], 0.0));
    store->addLoop("m", loop(ids[2], ids[1], 1.0));
  }
  auto store = db().open();  // across reopen
  const auto loops = store->loops("m");
  ASSERT_EQ(loops.size(), 4u);
  ASSERT_TRUE(loops[0].probability);
  EXPECT_EQ(*loops[0].probability, 0.8125);
  EXPECT_FALSE(loops[1].probability.has_value());
  ASSERT_TRUE(loops[2].probability);
  EXPECT_EQ(*loops[2].probability, 0.0);
  ASSERT_TRUE(loops[3].probability);
  EXPECT_EQ(*loops[3].probability, 1.0);
}

TEST_P(LoopProbabilityOnBothBackends, RefusesAProbabilityOutsideTheUnitIntervalAndStoresNothing) {
  auto store = db().open();
  const auto ids = scans(*store, 2);
  for (const double p : {-0.01, 1.0000001, std::numeric_limits<double>::quiet_NaN(),
                         std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()}) {
    SCOPED_TRACE(p);
    EXPECT_EQ(errorCode([&] { store->addLoop("m", loop(ids[1], ids[0], p)); }), StorageError::Code::kInvalidArgument);
  }
  EXPECT_TRUE(store->loops("m").empty());
}

// Runs SQL on a SQLite file behind the store's back.
void execSql(const std::string& path, const char* sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  EXPECT_EQ(sqlite3_exec(db, sql, nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  sqlite3_close(db);
}

TEST(LoopProbability, SqliteMigratesFromVersion7WithOldLoopsUnknown) {
  Backend backend("sqlite");
  std::vector<std::int64_t> ids;
  {
    auto store = backend.open();
    ids = scans(*store, 3);
    store->addLoop("m", loop(ids[2], ids[0], std::nullopt));
  }
  execSql(backend.options().path,
          "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN retired_bytes; "
          "ALTER TABLE loops DROP COLUMN probability; PRAGMA user_version=7;");
  auto store = backend.open();
  store->addLoop("m", loop(ids[2], ids[1], 0.75));
  const auto loops = store->loops("m");
  ASSERT_EQ(loops.size(), 2u);
  EXPECT_FALSE(loops[0].probability.has_value());  // recorded before the column: unknown, not invented
  ASSERT_TRUE(loops[1].probability);
  EXPECT_EQ(*loops[1].probability, 0.75);
  EXPECT_EQ(store->integrityCheck(), "ok");
}

TEST(LoopProbability, PostgresMigratesFromSchema3WithOldLoopsUnknown) {
  Backend backend("postgresql");
  if (!backend.unavailable().empty()) GTEST_SKIP() << backend.unavailable();
  std::vector<std::int64_t> ids;
  {
    auto store = backend.open();
    ids = scans(*store, 3);
    store->addLoop("m", loop(ids[2], ids[0], std::nullopt));
  }
  {
    pg::Conn conn(backend.options().path);
    conn.exec(
        "DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; ALTER TABLE maps DROP COLUMN retired_bytes; "
        "ALTER TABLE loops DROP COLUMN probability");
    conn.exec("UPDATE sglc_meta SET value = '3' WHERE key = 'schema_version'");
  }
  auto store = backend.open();
  pg::Conn conn(backend.options().path);
  EXPECT_EQ(conn.query("SELECT value FROM sglc_meta WHERE key = 'schema_version'").text(0, 0), "5");
  store->addLoop("m", loop(ids[2], ids[1], 0.75));
  const auto loops = store->loops("m");
  ASSERT_EQ(loops.size(), 2u);
  EXPECT_FALSE(loops[0].probability.has_value());
  ASSERT_TRUE(loops[1].probability);
  EXPECT_EQ(*loops[1].probability, 0.75);
}

INSTANTIATE_TEST_SUITE_P(MapStore, LoopProbabilityOnBothBackends, ::testing::Values("sqlite", "postgresql"),
                         [](const ::testing::TestParamInfo<std::string>& info) { return info.param; });

}  // namespace
}  // namespace sglc::storage
