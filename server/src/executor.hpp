// A fixed set of threads for the blocking work of streaming calls.
//
// Streams are served by gRPC's callback API, whose reactions must never block: an open stream holds no thread
// while it waits for its client. When a stream has a request to process (fingerprint, query, store), the
// reactor posts it here; tasks run first come first served on `threads` threads (engine work inside them is
// further bounded by the ComputePool).
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace sglc::server {

class Executor {
 public:
  explicit Executor(int threads);
  ~Executor();  // runs what is queued, then joins
  Executor(const Executor&) = delete;
  Executor& operator=(const Executor&) = delete;

  void post(std::function<void()> task);

 private:
  void loop();

  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<std::function<void()>> tasks_;
  bool stop_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace sglc::server
