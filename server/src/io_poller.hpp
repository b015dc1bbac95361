// A thread that keeps polling the server's network I/O.
//
// Once a server has callback methods (our streams), gRPC 1.51 stops polling the network from its sync-server
// threads and leaves it to the callback completion queue's threads, which sleep 100 ms after each second
// without an event. A server taking only unary calls then stalled every request that arrived in that window:
// about one round trip in 70 took ~100 ms longer (p99 104 ms against 23 ms before the streams moved to the
// callback API). A completion queue registered as frequently polled, with a thread that waits on it for good,
// keeps one thread in the poller at all times. Nothing is ever queued on it; it costs one idle thread.
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>
#include <thread>

namespace sglc::server {

class IoPoller {
 public:
  // Call before BuildAndStart; start() after it.
  explicit IoPoller(grpc::ServerBuilder& builder) : cq_(builder.AddCompletionQueue(/*is_frequently_polled=*/true)) {}
  ~IoPoller() { stop(); }
  IoPoller(const IoPoller&) = delete;
  IoPoller& operator=(const IoPoller&) = delete;

  void start() {
    thread_ = std::thread([this] {
      void* tag = nullptr;
      bool ok = false;
      while (cq_->Next(&tag, &ok)) {
      }
    });
  }
  // After the server's Shutdown(): ends the queue and joins the thread.
  void stop() {
    if (stopped_) return;
    stopped_ = true;
    cq_->Shutdown();
    if (thread_.joinable()) thread_.join();
  }

 private:
  std::unique_ptr<grpc::ServerCompletionQueue> cq_;
  std::thread thread_;
  bool stopped_ = false;
};

}  // namespace sglc::server
