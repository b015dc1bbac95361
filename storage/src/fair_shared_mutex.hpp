// A reader-writer lock that does not starve writers: a waiting writer holds the turnstile, so readers that
// arrive after it wait until it is done. (glibc's rwlock prefers readers; under constant queries an ingest
// could wait indefinitely.) Meets the SharedMutex requirements used by std::shared_lock / std::unique_lock.
#pragma once

#include <mutex>
#include <shared_mutex>

namespace sglc::storage {

class FairSharedMutex {
 public:
  void lock() {
    turnstile_.lock();
    rw_.lock();
    turnstile_.unlock();
  }
  void unlock() { rw_.unlock(); }
  void lock_shared() {
    turnstile_.lock();
    turnstile_.unlock();
    rw_.lock_shared();
  }
  void unlock_shared() { rw_.unlock_shared(); }

 private:
  std::mutex turnstile_;
  std::shared_mutex rw_;
};

}  // namespace sglc::storage
