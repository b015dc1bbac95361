#include "reader_pool.hpp"

namespace sglc::storage {

ReaderPool::Lease ReaderPool::acquire() const {
  {
    std::lock_guard lock(mutex_);
    if (!idle_.empty()) {
      sql::Db db = std::move(idle_.back());
      idle_.pop_back();
      return Lease(*this, std::move(db));
    }
  }
  return Lease(*this, sql::Db(path_, SQLITE_OPEN_READONLY, busy_timeout_ms_));
}

void ReaderPool::release(sql::Db db) const {
  std::lock_guard lock(mutex_);
  if (idle_.size() < kKept) idle_.push_back(std::move(db));
}

}  // namespace sglc::storage
