// The map-store back-ends a storage test runs on: a SQLite file in a fresh directory, or a fresh database in the
// throw-away PostgreSQL cluster that CTest starts around the storage tests (pg_cluster.sh; its URL is in the
// file SGLC_TEST_PG names).
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>

#include "postgres.hpp"
#include "storage_test_util.hpp"

namespace sglc::storage::testing {

// The test cluster's URL (its "postgres" database), or "" with `why` set when there is none.
inline std::string testClusterUrl(std::string& why) {
  const char* file = std::getenv("SGLC_TEST_PG");
  if (!file) {
    why =
        "no PostgreSQL test cluster: run the tests through ctest, which starts one, or set SGLC_TEST_PG to a file "
        "holding a server URL";
    return "";
  }
  std::ifstream in(file);
  std::string url;
  std::getline(in, url);
  if (url.empty()) why = std::string("SGLC_TEST_PG names ") + file + ", which holds no URL (did pg_cluster.sh start?)";
  return url;
}

class Backend {
 public:
  explicit Backend(const std::string& kind) : postgres_(kind == "postgresql") {
    if (!postgres_) return;
    std::string why;
    const auto server = testClusterUrl(why);
    if (server.empty()) {
      unavailable_ = why;
      return;
    }
    static std::atomic<int> counter{0};
    name_ = "sglc_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
    admin_ = std::make_unique<pg::Conn>(server);
    admin_->exec("DROP DATABASE IF EXISTS " + name_);
    admin_->exec("CREATE DATABASE " + name_);
    base_ = server.substr(0, server.rfind('/') + 1);
  }
  ~Backend() {
    if (!admin_) return;
    extra_.push_back(name_);
    for (const auto& d : extra_) admin_->exec("DROP DATABASE IF EXISTS " + d + " WITH (FORCE)");
  }
  Backend(const Backend&) = delete;
  Backend& operator=(const Backend&) = delete;

  // Empty when the back-end can be used, else why not (the test is skipped with it).
  const std::string& unavailable() const { return unavailable_; }
  bool postgres() const { return postgres_; }

  StoreOptions options() const { return testing::options(postgres_ ? base_ + name_ : dir_.file("map.db")); }
  std::unique_ptr<MapStore> open() const { return MapStore::open(options()); }
  // A path for files the test writes (backups).
  std::string file(const std::string& name) const { return dir_.file(name); }
  // Options of a store on a copy restored from `backup` (written by MapStore::backup).
  StoreOptions restored(const std::string& backup) {
    if (!postgres_) return testing::options(backup);
    const auto copy = name_ + "_restored";
    admin_->exec("CREATE DATABASE " + copy);
    extra_.push_back(copy);
    const auto cmd = "pg_restore --no-owner --exit-on-error -d '" + base_ + copy + "' '" + backup + "'";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    return testing::options(base_ + copy);
  }
  // Forces the next open to rebuild the indexes from the database (SQLite keeps snapshots; PostgreSQL always
  // rebuilds).
  void forgetSnapshots() const {
    if (!postgres_) std::filesystem::remove_all(dir_.file("map.db") + ".index");
  }

 private:
  bool postgres_;
  TempDir dir_;
  std::string unavailable_, name_, base_;
  std::unique_ptr<pg::Conn> admin_;
  std::vector<std::string> extra_;  // restored copies
};

// Ends the sessions holding an advisory lock (a map's graph lock) in the connection's own database: a network
// blip as the store sees it. The cluster is shared by the tests CTest runs beside each other, so never wider.
inline constexpr const char* kEndThisDatabasesLockHolders =
    "SELECT pg_terminate_backend(pid) FROM pg_locks WHERE locktype = 'advisory' AND granted"
    " AND database = (SELECT oid FROM pg_database WHERE datname = current_database())";

// A test that runs once per back-end: TEST_P(OnBothBackends, Name) { auto store = db().open(); ... }
class OnBothBackends : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    backend_ = std::make_unique<Backend>(GetParam());
    if (!backend_->unavailable().empty()) GTEST_SKIP() << backend_->unavailable();
  }
  Backend& db() { return *backend_; }

 private:
  std::unique_ptr<Backend> backend_;
};

}  // namespace sglc::storage::testing
