#include "executor.hpp"

#include <spdlog/spdlog.h>

#include "sglc/log/log_line.hpp"

namespace sglc::server {

Executor::Executor(int threads) {
  for (int i = 0; i < std::max(1, threads); ++i) threads_.emplace_back([this] { loop(); });
}

Executor::~Executor() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  ready_.notify_all();
  for (auto& t : threads_) t.join();
}

void Executor::post(std::function<void()> task) {
  {
    std::lock_guard lock(mutex_);
    tasks_.push_back(std::move(task));
  }
  ready_.notify_one();
}

void Executor::loop() {
  std::unique_lock lock(mutex_);
  for (;;) {
    ready_.wait(lock, [&] { return stop_ || !tasks_.empty(); });
    if (tasks_.empty()) return;  // stopping, nothing left
    auto task = std::move(tasks_.front());
    tasks_.pop_front();
    lock.unlock();
    try {
      task();
    } catch (const std::exception& e) {
      // Tasks handle their own errors: one that escapes is a bug, logged like every other line (JSON).
      spdlog::error("{}", logging::logLine({{"event", "executor_task_threw"}, {"error", e.what()}}));
    }
    lock.lock();
  }
}

}  // namespace sglc::server
