// The HTTP/1.1 endpoint for Prometheus scrapes, on Boost.Beast: GET (or HEAD) /metrics answers the text
// exposition, any other path 404, any other method 405, a malformed or incomplete request 400 (lines must end
// in CRLF), a request head over kMaxRequestBytes 431. Connections are served concurrently on one thread of
// asynchronous I/O, each with Limits::request_timeout to send its request head; every answer closes the
// connection, after the server has read what the client still sends (up to kDrainBytes for
// Limits::drain_timeout), so that an answer is not lost to a TCP reset. A peer (an IPv4 address, an IPv6 /64)
// holds at most Limits::max_per_peer connections and the server at most Limits::max_connections; a newcomer
// beyond either takes the slot of the oldest connection still waiting for its request (ConnectionSlots), and
// is refused only when every slot is busy answering.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <string>

namespace sglc::server {

// What the endpoint serves: `render` gives the exposition; `refresh`, when set, is called first and returns a
// check that says when fresh values are there (GaugeRefresher::request): the answer waits for it at most
// Limits::fresh_wait, polling, without holding the thread, then renders what there is.
struct MetricsSource {
  std::function<std::string()> render;
  std::function<std::function<bool()>()> refresh;
};

struct MetricsHttpLimits {
  std::chrono::milliseconds request_timeout{2000};  // to send the whole request head
  std::chrono::milliseconds fresh_wait{1000};       // for MetricsSource::refresh's values
  std::chrono::milliseconds drain_timeout{1000};    // to read what the client sends after the answer
  int max_connections = 256;
  int max_per_peer = 16;
};

class MetricsHttpServer {
 public:
  static constexpr std::size_t kMaxRequestBytes = 8192;
  static constexpr std::size_t kDrainBytes = 1 << 20;

  using Limits = MetricsHttpLimits;

  // Binds host:port (port 0: any free port) and starts serving. Throws std::runtime_error naming the address
  // when it cannot listen.
  MetricsHttpServer(const std::string& address, MetricsSource source, Limits limits = {});
  MetricsHttpServer(const std::string& address, std::function<std::string()> render)
      : MetricsHttpServer(address, MetricsSource{std::move(render), {}}) {}
  ~MetricsHttpServer();  // stops serving; connections still open are closed
  MetricsHttpServer(const MetricsHttpServer&) = delete;
  MetricsHttpServer& operator=(const MetricsHttpServer&) = delete;

  int port() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace sglc::server
