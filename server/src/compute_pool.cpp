#include "compute_pool.hpp"

#include <chrono>

#include "rpc_error.hpp"

namespace sglc::server {

ComputePool::ComputePool(int threads) : threads_(std::max(1, threads)) {
  for (int i = 1; i < threads_; ++i) helpers_.emplace_back([this] { helperLoop(); });
}

ComputePool::~ComputePool() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  for (auto& t : helpers_) t.join();
}

void ComputePool::Slot::release() {
  if (!pool_) return;
  {
    std::lock_guard lock(pool_->mutex_);
    pool_->freeSlot();
  }
  pool_->changed_.notify_all();
  pool_ = nullptr;
}

// With the mutex held: hands the slot to the longest-waiting call, or returns it to the pool.
void ComputePool::freeSlot() {
  if (!waiters_.empty()) {
    *waiters_.front() = true;  // busy_ is unchanged: the slot changes hands
    waiters_.pop_front();
  } else {
    --busy_;
  }
}

ComputePool::Slot ComputePool::acquire(std::chrono::system_clock::time_point deadline,
                                       const std::function<bool()>& cancelled) {
  std::unique_lock lock(mutex_);
  if (busy_ < threads_ && waiters_.empty()) {
    ++busy_;
    return Slot(this);
  }
  // First come, first served: wait in line until a releasing call hands its slot over.
  auto granted = std::make_shared<bool>(false);
  waiters_.push_back(granted);
  while (!*granted) {
    // Wake up now and then to notice a cancelled call or a passed deadline.
    changed_.wait_for(lock, std::chrono::milliseconds(20));
    if (*granted) break;
    const bool gone = cancelled();
    if (gone || std::chrono::system_clock::now() > deadline) {
      std::erase(waiters_, granted);
      if (gone) throw RpcError(grpc::StatusCode::CANCELLED, "the client cancelled the call");
      throw RpcError(grpc::StatusCode::DEADLINE_EXCEEDED,
                     "deadline exceeded while waiting for a compute thread (server busy); nothing was stored");
    }
  }
  return Slot(this);
}

int ComputePool::busy() const {
  std::lock_guard lock(mutex_);
  return busy_;
}

int ComputePool::waiting() const {
  std::lock_guard lock(mutex_);
  return static_cast<int>(waiters_.size());
}

void ComputePool::runItems(Job& job) {
  for (std::size_t i; !job.failed.load() && (i = job.next.fetch_add(1)) < job.n;) {
    try {
      (*job.fn)(i);
    } catch (...) {
      std::lock_guard lock(mutex_);
      if (!job.error) job.error = std::current_exception();
      job.failed = true;
    }
  }
}

void ComputePool::parallelFor(std::size_t n, const std::function<void(std::size_t)>& fn) {
  if (n == 0) return;
  auto job = std::make_shared<Job>();
  job->fn = &fn;
  job->n = n;
  if (n > 1 && threads_ > 1) {
    {
      std::lock_guard lock(mutex_);
      jobs_.push_back(job);
    }
    changed_.notify_all();
  }
  runItems(*job);
  {
    std::unique_lock lock(mutex_);
    std::erase(jobs_, job);
    changed_.wait(lock, [&] { return job->running == 0; });
  }
  if (job->error) std::rethrow_exception(job->error);
}

void ComputePool::helperLoop() {
  std::unique_lock lock(mutex_);
  for (;;) {
    // Calls waiting for a slot go first: a helper only takes a slot nobody is queued for.
    changed_.wait(lock, [&] { return stop_ || (!jobs_.empty() && busy_ < threads_ && waiters_.empty()); });
    if (stop_) return;
    auto job = jobs_.front();
    if (job->next.load() >= job->n || job->failed.load()) {  // nothing left to take (its caller finishes it)
      jobs_.pop_front();
      continue;
    }
    ++busy_;
    ++job->running;
    lock.unlock();
    runItems(*job);
    lock.lock();
    freeSlot();
    --job->running;
    changed_.notify_all();
  }
}

}  // namespace sglc::server
