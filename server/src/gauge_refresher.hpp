// Reads a Metrics registry's gauges on a thread of its own, when a scrape asks for fresh values, so that a
// scrape never runs a gauge reader itself: a map database that does not answer delays the refresh, not the
// scrape, which is then served the values read before (their age is in the exposition).
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>

#include "metrics.hpp"

namespace sglc::server {

class GaugeRefresher {
 public:
  // Starts the thread and a first refresh.
  explicit GaugeRefresher(Metrics& metrics);
  ~GaugeRefresher();  // waits for a refresh in progress (its readers may still use what they read)
  GaugeRefresher(const GaugeRefresher&) = delete;
  GaugeRefresher& operator=(const GaugeRefresher&) = delete;

  // Asks for values read from now on (a refresh in progress is not enough: it may have read its values
  // before), and returns a check that is true once they are there. Never blocks. One refresh serves every
  // request made before it started, so a flood of scrapes costs one refresh at a time, back to back.
  std::function<bool()> request();

 private:
  void run();

  Metrics& metrics_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::uint64_t requested_ = 0;  // the newest generation asked for
  std::uint64_t finished_ = 0;   // the newest generation whose refresh has finished
  bool running_ = false;         // generation finished_ + 1 is being read
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace sglc::server
