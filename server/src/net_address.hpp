// The server's small HTTP endpoints (metrics, live view): their addresses, listening and accepting, and what one
// peer is for their per-peer connection limits.
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/address.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <utility>

#include "connection_slots.hpp"

namespace sglc::server {

// Splits "host:port" ("[::1]:9090" for IPv6). Throws std::runtime_error naming `what` and the address when there
// is no port or it is not a number 0..65535.
std::pair<std::string, std::string> hostPort(const std::string& address, const std::string& what);

// Opens, binds (reusing the address) and listens on host:port, the first of its addresses that works; returns the
// port (the one chosen for port 0). Throws std::runtime_error naming `what`, the address and why.
int listenOn(boost::asio::ip::tcp::acceptor& acceptor, const std::string& address, const std::string& what);

// Accepts connections until the acceptor is closed or its io_context stops, handing each to `admit` (one that
// throws loses that connection only). An accept error (out of descriptors: the connection stays queued) pauses
// 100 ms on `backoff`, then accepting goes on.
void acceptForever(boost::asio::ip::tcp::acceptor& acceptor, boost::asio::steady_timer& backoff,
                   std::function<void(boost::asio::ip::tcp::socket)> admit);

// Runs `io` on a new thread until it is stopped; a handler that throws (out of memory) loses its connection only.
std::thread runIo(boost::asio::io_context& io);

// One peer: an IPv4 address (also when it comes IPv4-mapped), or an IPv6 /64 (what one host or site is given).
std::string peerKey(const boost::asio::ip::address& a);

// One small endpoint's I/O: an io_context on a thread of its own, its acceptor and the accept back-off. Declare it
// after what its connections use: destroying it destroys the connections still open.
class TcpEndpoint {
 public:
  TcpEndpoint() = default;
  ~TcpEndpoint() { stop(); }
  TcpEndpoint(const TcpEndpoint&) = delete;
  TcpEndpoint& operator=(const TcpEndpoint&) = delete;

  // Binds host:port (listenOn: throws naming `what`), accepts into `admit`, and starts the thread.
  void start(const std::string& address, const std::string& what,
             std::function<void(boost::asio::ip::tcp::socket)> admit) {
    port_ = listenOn(acceptor_, address, what);
    acceptForever(acceptor_, backoff_, std::move(admit));
    thread_ = runIo(io);
  }
  // Stops the thread (handlers no longer run); once only.
  void stop() {
    io.stop();
    if (thread_.joinable()) thread_.join();
  }
  int port() const { return port_; }

  boost::asio::io_context io{1};

 private:
  boost::asio::ip::tcp::acceptor acceptor_{io};
  boost::asio::steady_timer backoff_{io};
  int port_ = 0;
  std::thread thread_;
};

// Admits a connection into `slots` (its peer: peerKey of its address) and `open`: the connections whose slots it
// took are told to evict(), then `make(socket, id)` gives its session (a shared_ptr to Session), which is kept
// (weakly) and start()ed. Returns false when every slot is busy answering: the socket is closed unanswered.
template <class Session, class Make>
bool admitConnection(ConnectionSlots& slots, std::map<ConnectionSlots::Id, std::weak_ptr<Session>>& open,
                     boost::asio::ip::tcp::socket socket, Make make) {
  boost::system::error_code ec;
  const auto peer = socket.remote_endpoint(ec);
  if (ec) return true;  // already gone
  const auto admission = slots.admit(peerKey(peer.address()));
  if (!admission) return false;
  for (const auto id : admission->evicted)
    if (const auto it = open.find(id); it != open.end())
      if (const auto evicted = it->second.lock()) evicted->evict();
  std::shared_ptr<Session> session;
  try {
    session = make(std::move(socket), admission->id);
  } catch (...) {
    slots.leave(admission->id);
    throw;
  }
  open[admission->id] = session;
  session->start();
  return true;
}

}  // namespace sglc::server
