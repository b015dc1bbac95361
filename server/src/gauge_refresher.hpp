// Reads a Metrics registry's gauges on a thread of its own, when a scrape asks for fresh values, so that a
// scrape never runs a gauge reader itself: a map database that does not answer delays the refresh, not the
// scrape, which is then served the values read before (their age is in the exposition).
#pragma once

#include <chrono>
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

  // Refreshes start at least this far apart: a flood of scrapes costs the database at most 4 reads a second,
  // and a scrape (which waits up to a second for fresh values) still gets values read after it asked.
  static constexpr std::chrono::milliseconds kMinInterval{250};

  // Asks for values read from now on (a refresh in progress is not enough: it may have read its values
  // before), and returns a check that is true once they are there. Never blocks. One refresh serves every
  // request made before it started.
  std::function<bool()> request();

 private:
  void run();

  Metrics& metrics_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::uint64_t requested_ = 0;  // the newest generation asked for
  std::uint64_t finished_ = 0;   // the newest generation whose refresh has finished
  bool running_ = false;         // generation finished_ + 1 is being read
  std::chrono::steady_clock::time_point finished_at_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace sglc::server
