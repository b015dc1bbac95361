#include "memory_budget.hpp"

#include <malloc.h>

#include <algorithm>

#include "rpc_error.hpp"

namespace sglc::server {

MemoryBudget::Lease& MemoryBudget::Lease::operator=(Lease&& o) noexcept {
  if (this != &o) {
    release();
    budget_ = o.budget_;
    bytes_ = o.bytes_;
    o.budget_ = nullptr;
  }
  return *this;
}

void MemoryBudget::Lease::release() {
  if (budget_ && bytes_) budget_->give(bytes_);
  budget_ = nullptr;
  bytes_ = 0;
}

void MemoryBudget::take(std::size_t bytes, std::size_t held, std::chrono::system_clock::time_point deadline,
                        const std::function<bool()>& cancelled, std::chrono::milliseconds max_wait) {
  const auto give_up = std::chrono::system_clock::now() + max_wait;
  std::unique_lock lock(mutex_);
  const auto ticket = next_ticket_++;
  queue_.push_back(ticket);
  for (;;) {
    if (queue_.front() == ticket && fits(bytes, held)) break;
    const auto now = std::chrono::system_clock::now();
    RpcError error(grpc::StatusCode::OK, "");
    if (now > deadline)
      error = RpcError(grpc::StatusCode::DEADLINE_EXCEEDED,
                       "deadline exceeded while waiting for scan memory (the server is busy); nothing was stored");
    else if (cancelled())
      error = RpcError(grpc::StatusCode::CANCELLED, "the client cancelled the call");
    else if (now > give_up)
      error = RpcError(grpc::StatusCode::RESOURCE_EXHAUSTED,
                       "the server's in-flight scan memory (" + std::to_string(capacity_ >> 20) +
                           " MB) stayed in use for too long; retry later; nothing was stored");
    if (error.code() != grpc::StatusCode::OK) {
      queue_.erase(std::find(queue_.begin(), queue_.end(), ticket));
      lock.unlock();
      changed_.notify_all();
      throw error;
    }
    changed_.wait_until(lock, std::min({now + std::chrono::milliseconds(20), deadline, give_up}));
  }
  queue_.pop_front();
  used_ += bytes;
  peak_ = std::max(peak_, used_);
  high_water_ = std::max(high_water_, used_);
  lock.unlock();
  changed_.notify_all();
}

MemoryBudget::Lease MemoryBudget::acquire(std::size_t bytes, std::chrono::system_clock::time_point deadline,
                                          const std::function<bool()>& cancelled, std::chrono::milliseconds max_wait) {
  Lease lease;
  lease.budget_ = this;
  grow(lease, bytes, deadline, cancelled, max_wait);
  return lease;
}

void MemoryBudget::grow(Lease& lease, std::size_t bytes, std::chrono::system_clock::time_point deadline,
                        const std::function<bool()>& cancelled, std::chrono::milliseconds max_wait) {
  if (!bytes) return;
  take(bytes, lease.budget_ ? lease.bytes_ : 0, deadline, cancelled, max_wait);
  lease.budget_ = this;
  lease.bytes_ += bytes;
}

void MemoryBudget::shrink(Lease& lease, std::size_t bytes) {
  if (lease.budget_ != this || lease.bytes_ <= bytes) return;
  give(lease.bytes_ - bytes);
  lease.bytes_ = bytes;
}

void MemoryBudget::give(std::size_t bytes) {
  {
    std::lock_guard lock(mutex_);
    used_ -= std::min(used_, bytes);
    if (used_ == 0) idle_since_ = std::chrono::steady_clock::now();
  }
  changed_.notify_all();
}

std::size_t MemoryBudget::inUse() const {
  std::lock_guard lock(mutex_);
  return used_;
}

std::size_t MemoryBudget::peak() const {
  std::lock_guard lock(mutex_);
  return peak_;
}

void MemoryBudget::trim() {
  {
    std::lock_guard lock(mutex_);
    if (used_ > 0 || high_water_ < kTrimAfterBytes || std::chrono::steady_clock::now() - idle_since_ < kTrimIdle)
      return;
    high_water_ = 0;
  }
  ::malloc_trim(0);
}

}  // namespace sglc::server
