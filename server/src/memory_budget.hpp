// A budget for the scan bytes the server holds in flight.
//
// Every call that carries a scan reserves its cost (wire bytes x kScanCostFactor: the message, the decoded
// scan, the engine's working copies) before it decodes the scan, and returns it when done. Calls beyond the
// budget wait, first come first served, within their deadline; a single scan larger than the whole budget is
// admitted alone. So the memory a burst of large scans takes is bounded by the budget rather than by
// max_calls x message size. When the last reservation of a burst is returned, trim() gives freed heap back to
// the system (glibc keeps it otherwise).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>

namespace sglc::server {

inline constexpr std::size_t kScanCostFactor = 3;

class MemoryBudget {
 public:
  explicit MemoryBudget(std::size_t bytes) : capacity_(bytes) {}

  class Lease {
   public:
    Lease() = default;
    Lease(Lease&& o) noexcept : budget_(o.budget_), bytes_(o.bytes_) { o.budget_ = nullptr; }
    Lease& operator=(Lease&& o) noexcept;
    ~Lease() { release(); }
    void release();
    std::size_t bytes() const { return bytes_; }

   private:
    friend class MemoryBudget;
    MemoryBudget* budget_ = nullptr;
    std::size_t bytes_ = 0;
  };

  // Waits until `bytes` fit (or nothing else is in flight), while !cancelled() and before `deadline`; throws
  // RpcError: DEADLINE_EXCEEDED / CANCELLED, or RESOURCE_EXHAUSTED after `max_wait`.
  Lease acquire(std::size_t bytes, std::chrono::system_clock::time_point deadline,
                const std::function<bool()>& cancelled, std::chrono::milliseconds max_wait = std::chrono::seconds(30));
  // Adds `bytes` to a lease (chunked uploads grow as chunks arrive), waiting like acquire.
  void grow(Lease& lease, std::size_t bytes, std::chrono::system_clock::time_point deadline,
            const std::function<bool()>& cancelled, std::chrono::milliseconds max_wait = std::chrono::seconds(30));
  // Returns what a lease holds beyond `bytes` (a reservation made for the largest case, once the real size is
  // known).
  void shrink(Lease& lease, std::size_t bytes);

  std::size_t capacity() const { return capacity_; }
  std::size_t inUse() const;
  std::size_t peak() const;
  // Returns freed heap to the system once a burst has ended: more than kTrimAfterBytes were in flight at once
  // since the last trim, and nothing has been for kTrimIdle. Cheap otherwise. Steady traffic of ordinary scans
  // never trims (trimming gives pages back that the next call would fault in again).
  void trim();
  static constexpr std::size_t kTrimAfterBytes = std::size_t{64} << 20;
  static constexpr std::chrono::milliseconds kTrimIdle{1500};

 private:
  // `held`: what the caller's lease already holds (a lease alone in flight may grow past the budget).
  void take(std::size_t bytes, std::size_t held, std::chrono::system_clock::time_point deadline,
            const std::function<bool()>& cancelled, std::chrono::milliseconds max_wait);
  bool fits(std::size_t bytes, std::size_t held) const { return used_ == held || used_ + bytes <= capacity_; }
  void give(std::size_t bytes);

  const std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::size_t used_ = 0, peak_ = 0;
  std::deque<std::uint64_t> queue_;  // waiting callers, oldest first
  std::uint64_t next_ticket_ = 0;
  std::size_t high_water_ = 0;  // most in flight at once since the last trim
  std::chrono::steady_clock::time_point idle_since_ = std::chrono::steady_clock::now();
};

}  // namespace sglc::server
