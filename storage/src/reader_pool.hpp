// Read-only connections to the map database, pooled: readers run beside the writer (WAL) and beside each
// other, each on its own connection.
#pragma once

#include <mutex>
#include <string>
#include <vector>

#include "sqlite.hpp"

namespace sglc::storage {

class ReaderPool {
 public:
  ReaderPool(std::string path, int busy_timeout_ms) : path_(std::move(path)), busy_timeout_ms_(busy_timeout_ms) {}

  // A connection for one caller, returned to the pool (up to kKept of them) when the lease ends.
  class Lease {
   public:
    Lease(const ReaderPool& pool, sql::Db db) : pool_(pool), db_(std::move(db)) {}
    Lease(Lease&&) = default;
    ~Lease() {
      if (db_) pool_.release(std::move(db_));
    }
    const sql::Db& operator*() const { return db_; }

   private:
    const ReaderPool& pool_;
    sql::Db db_;
  };

  Lease acquire() const;

 private:
  static constexpr std::size_t kKept = 16;
  void release(sql::Db db) const;

  const std::string path_;
  const int busy_timeout_ms_;
  mutable std::mutex mutex_;
  mutable std::vector<sql::Db> idle_;
};

}  // namespace sglc::storage
