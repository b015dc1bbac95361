#include "gauge_refresher.hpp"

#include <algorithm>

namespace sglc::server {

GaugeRefresher::GaugeRefresher(Metrics& metrics) : metrics_(metrics), requested_(1), thread_([this] { run(); }) {}

GaugeRefresher::~GaugeRefresher() {
  {
    const std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

std::function<bool()> GaugeRefresher::request() {
  std::uint64_t wanted = 0;
  {
    const std::lock_guard lock(mutex_);
    wanted = finished_ + (running_ ? 2 : 1);
    requested_ = std::max(requested_, wanted);
  }
  wake_.notify_all();
  return [this, wanted] {
    const std::lock_guard lock(mutex_);
    return finished_ >= wanted;
  };
}

void GaugeRefresher::run() {
  std::unique_lock lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || requested_ > finished_; });
    if (finished_ > 0) wake_.wait_until(lock, finished_at_ + kMinInterval, [this] { return stop_; });
    if (stop_) return;
    // Serves every request made until now; one made while it runs asks for the generation after it.
    running_ = true;
    lock.unlock();
    metrics_.refreshGauges();
    lock.lock();
    running_ = false;
    finished_ += 1;
    finished_at_ = std::chrono::steady_clock::now();
  }
}

}  // namespace sglc::server
