// A minimal HTTP/1.1 endpoint for Prometheus scrapes: GET (or HEAD) /metrics answers the text exposition,
// any other path 404, any other method 405, a malformed or oversized request 400/431. One thread serves
// connections one at a time; each gets kRequestTimeout to send its request, then is closed (a scrape is one
// small request; the port is meant for a trusted network or loopback). Every response closes the connection.
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <thread>

namespace sglc::server {

class MetricsHttpServer {
 public:
  static constexpr std::chrono::milliseconds kRequestTimeout{2000};
  static constexpr std::size_t kMaxRequestBytes = 8192;

  // Binds host:port (port 0: any free port) and starts serving `render`'s text. Throws std::runtime_error
  // naming the address when it cannot listen.
  MetricsHttpServer(const std::string& address, std::function<std::string()> render);
  ~MetricsHttpServer();  // stops serving
  MetricsHttpServer(const MetricsHttpServer&) = delete;
  MetricsHttpServer& operator=(const MetricsHttpServer&) = delete;

  int port() const { return port_; }

 private:
  void serve();
  void answer(int fd) const;

  std::function<std::string()> render_;
  int listen_fd_ = -1;
  int wake_[2] = {-1, -1};  // a pipe: written to stop the thread
  int port_ = 0;
  std::thread thread_;
};

}  // namespace sglc::server
