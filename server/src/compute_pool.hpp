// Bounds the CPU work of the server to a fixed number of threads, and lends idle ones to a busy call.
//
// RPC threads are cheap (most wait on the network or hold an open stream); engine work is not. A call takes
// a slot with acquire() before fingerprinting or verifying and gives it back before it writes to the
// database, so at most `threads` calls compute at once and the rest wait their turn, first come first
// served (honouring their deadline and cancellation), instead of being refused. Inside a call,
// parallelFor() spreads independent items (candidate verifications, refinements) over the calling thread
// and the pool's helper threads, but a helper only joins while a slot is free and no call waits for one:
// under load every call runs on its own thread and nothing is oversubscribed.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace sglc::server {

class ComputePool {
 public:
  // threads >= 1: compute slots; threads - 1 helper threads are started.
  explicit ComputePool(int threads);
  ~ComputePool();
  ComputePool(const ComputePool&) = delete;
  ComputePool& operator=(const ComputePool&) = delete;

  class Slot {
   public:
    Slot(Slot&& other) noexcept : pool_(other.pool_) { other.pool_ = nullptr; }
    Slot& operator=(Slot&&) = delete;
    ~Slot() { release(); }
    void release();

   private:
    friend class ComputePool;
    explicit Slot(ComputePool* pool) : pool_(pool) {}
    ComputePool* pool_;
  };

  // Waits for a free slot. Throws RpcError (CANCELLED / DEADLINE_EXCEEDED) when `cancelled` turns true or the
  // deadline passes while waiting (both are checked every 20 ms).
  Slot acquire(std::chrono::system_clock::time_point deadline, const std::function<bool()>& cancelled);
  // The call's deadline and cancellation; `ctx` may be null (wait as long as it takes).
  Slot acquire(const grpc::ServerContextBase* ctx) {
    if (!ctx) return acquire(std::chrono::system_clock::time_point::max(), [] { return false; });
    return acquire(ctx->deadline(), [ctx] { return ctx->IsCancelled(); });
  }
  // Slots in use and calls waiting for one (for tests and stats).
  int busy() const;
  int waiting() const;

  // Runs fn(i) for every i in [0, n) and returns when all are done; the caller must hold a slot. Items may run
  // in any order and at once: fn must only write to its own item. The first exception thrown by an item is
  // rethrown here (items not started yet are skipped).
  void parallelFor(std::size_t n, const std::function<void(std::size_t)>& fn);

  int threads() const { return threads_; }

 private:
  struct Job {
    const std::function<void(std::size_t)>* fn = nullptr;
    std::size_t n = 0;
    std::atomic<std::size_t> next{0};
    int running = 0;  // helpers inside the job (guarded by the pool mutex)
    std::exception_ptr error;
    std::atomic<bool> failed{false};
  };
  void runItems(Job& job);
  void freeSlot();
  void helperLoop();

  const int threads_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  int busy_ = 0;                               // slots in use (calls + helpers at work)
  std::deque<std::shared_ptr<bool>> waiters_;  // calls waiting for a slot, oldest first; set true when granted
  std::deque<std::shared_ptr<Job>> jobs_;
  bool stop_ = false;
  std::vector<std::thread> helpers_;
};

}  // namespace sglc::server
