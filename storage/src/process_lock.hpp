// One process per map database: an exclusive lock on `<database>.lock`, which holds the owner's pid.
//
// SQLite would let a second process open the same file and write to it; two servers on one map then keep
// diverging descriptor indexes. The lock is an flock(2), so the kernel releases it when the owner exits or is
// killed: a crash never leaves a stale lock behind (the file stays, unlocked).
#pragma once

#include <string>

namespace sglc::storage {

class ProcessLock {
 public:
  // Takes the lock for `database` or throws StorageError: kBusy "... in use by process N" when another process
  // (or another open store in this process) holds it, kReadOnly when the lock file cannot be created.
  explicit ProcessLock(const std::string& database);
  ProcessLock() = default;
  ProcessLock(ProcessLock&& other) noexcept : fd_(other.fd_) { other.fd_ = -1; }
  ProcessLock& operator=(ProcessLock&& other) noexcept;
  ProcessLock(const ProcessLock&) = delete;
  ~ProcessLock();

 private:
  int fd_ = -1;
};

}  // namespace sglc::storage
