// Thin RAII wrappers over the SQLite C API that turn every failure into a StorageError with a code.
#pragma once

#include <sqlite3.h>

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "sglc/storage/map_store.hpp"

namespace sglc::storage::sql {

// Maps an SQLite result code to a StorageError code.
StorageError::Code classify(int rc);
// What a failure of that kind means for the caller, in words without SQL or paths.
std::string meaning(StorageError::Code code);
// Throws StorageError(code, meaning(code), detail: `what` and SQLite's message).
[[noreturn]] void fail(sqlite3* db, int rc, const std::string& what);

class Db {
 public:
  Db() = default;
  Db(const std::string& path, int flags, int busy_timeout_ms);
  Db(Db&& other) noexcept : db_(other.db_) { other.db_ = nullptr; }
  Db& operator=(Db&& other) noexcept;
  ~Db();
  sqlite3* get() const { return db_; }
  void exec(const std::string& sql) const;
  explicit operator bool() const { return db_ != nullptr; }

 private:
  sqlite3* db_ = nullptr;
};

class Stmt {
 public:
  Stmt(const Db& db, const char* sql);
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;
  ~Stmt();

  Stmt& bind(int i, std::int64_t v);
  Stmt& bind(int i, double v);
  Stmt& bind(int i, const std::string& v);
  Stmt& bindBlob(int i, std::span<const std::uint8_t> v);
  Stmt& bindNull(int i);
  // True while a row is available.
  bool step();
  // Runs a statement that returns no rows.
  void run();
  void reset();

  bool isNull(int col) const { return sqlite3_column_type(stmt_, col) == SQLITE_NULL; }
  std::int64_t i64(int col) const { return sqlite3_column_int64(stmt_, col); }
  double f64(int col) const { return sqlite3_column_double(stmt_, col); }
  std::string text(int col) const;
  std::span<const std::uint8_t> blob(int col) const;

 private:
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
};

// BEGIN IMMEDIATE ... COMMIT, rolled back on destruction unless committed.
class Transaction {
 public:
  explicit Transaction(const Db& db);
  ~Transaction();
  void commit();

 private:
  const Db& db_;
  bool done_ = false;
};

}  // namespace sglc::storage::sql
