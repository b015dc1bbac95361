#include "metrics_http.hpp"

#include <algorithm>

#include <array>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core/error.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/empty_body.hpp>
#include <boost/beast/http/error.hpp>
#include <boost/beast/http/parser.hpp>
#include <boost/beast/http/read.hpp>
#include <map>
#include <stdexcept>
#include <thread>

#include "connection_slots.hpp"
#include "net_address.hpp"

namespace sglc::server {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;
using Clock = std::chrono::steady_clock;
using Server = MetricsHttpServer;

constexpr std::chrono::milliseconds kWriteTimeout{5000};
constexpr std::chrono::milliseconds kFreshPoll{20};

std::string response(int code, const char* reason, const std::string& body, bool head_only,
                     const char* type = "text/plain; charset=utf-8") {
  std::string out = "HTTP/1.1 " + std::to_string(code) + ' ' + reason + "\r\nContent-Type: " + type +
                    "\r\nContent-Length: " + std::to_string(body.size()) + "\r\nConnection: close\r\n";
  if (code == 405) out += "Allow: GET, HEAD\r\n";
  out += "\r\n";
  if (!head_only) out += body;
  return out;
}

}  // namespace

namespace {
class Session;
}  // namespace

struct MetricsHttpServer::Impl {
  Impl(MetricsSource s, Limits l)
      : source(std::move(s)), limits(l), slots(limits.max_connections, limits.max_per_peer) {}

  void admit(tcp::socket socket);

  const MetricsSource source;
  const Limits limits;
  // The connections open (touched on the I/O thread only, and by the sessions that the io_context destroys
  // after it: declared before it, so they outlive it).
  ConnectionSlots slots;
  std::map<ConnectionSlots::Id, std::weak_ptr<Session>> sessions;
  TcpEndpoint net;  // last: its connections use the members above
};

namespace {

// One connection: read the request head within the deadline, answer, read what else comes, close.
class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(tcp::socket socket, Server::Impl& server, ConnectionSlots::Id id)
      : stream_(std::move(socket)), server_(server), id_(id), timer_(stream_.get_executor()) {
    parser_.header_limit(Server::kMaxRequestBytes);
  }
  ~Session() {
    server_.slots.leave(id_);
    server_.sessions.erase(id_);
  }
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  // Its slot went to a newcomer: close, which ends what it waits for.
  void evict() {
    beast::error_code ignored;
    stream_.socket().close(ignored);
    timer_.cancel();
  }

  void start() {
    stream_.expires_after(server_.limits.request_timeout);  // for the whole head: a slow sender is cut off
    http::async_read_header(stream_, buffer_, parser_,
                            [self = shared_from_this()](beast::error_code ec, std::size_t) { self->onHead(ec); });
  }

 private:
  void onHead(beast::error_code ec) {
    server_.slots.requestReceived(id_);  // answered from now on: not evicted
    if (ec == beast::error::timeout || ec == http::error::end_of_stream || ec == asio::error::operation_aborted)
      return;  // nothing (complete) came, or evicted
    if (ec == http::error::header_limit || ec == http::error::buffer_overflow)
      return reply(response(431, "Request Header Fields Too Large", "request too large\n", false));
    if (ec) return reply(response(400, "Bad Request", "malformed request (HTTP/1.x, lines end in CRLF)\n", false));
    const auto& request = parser_.get();
    head_only_ = request.method() == http::verb::head;
    if (request.method() != http::verb::get && !head_only_)
      return reply(response(405, "Method Not Allowed", "only GET and HEAD\n", false));
    const auto target = request.target();
    if (target.substr(0, target.find('?')) != "/metrics")
      return reply(response(404, "Not Found", "see /metrics\n", head_only_));
    if (server_.source.refresh) {
      fresh_ = server_.source.refresh();
      asked_ = Clock::now();
    }
    waitFresh();
  }

  // Polls for fresh gauges without holding the thread, up to Limits::fresh_wait; then answers with what there is.
  void waitFresh() {
    if (fresh_ && !fresh_() && Clock::now() - asked_ < server_.limits.fresh_wait) {
      timer_.expires_after(kFreshPoll);
      timer_.async_wait([self = shared_from_this()](beast::error_code ec) {
        if (!ec) self->waitFresh();
      });
      return;
    }
    reply(response(200, "OK", server_.source.render(), head_only_, "text/plain; version=0.0.4; charset=utf-8"));
  }

  void reply(std::string text) {
    out_ = std::move(text);
    stream_.expires_after(kWriteTimeout);
    asio::async_write(stream_, asio::buffer(out_), [self = shared_from_this()](beast::error_code ec, std::size_t) {
      if (!ec) self->drain();
    });
  }

  // The answer is sent: end our side, and read (and drop) what the client still sends until it closes, so that
  // closing with unread bytes does not reset the connection before the client has read the answer.
  void drain() {
    beast::error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    stream_.expires_after(server_.limits.drain_timeout);
    readDrain();
  }
  void readDrain() {
    stream_.async_read_some(asio::buffer(scratch_), [self = shared_from_this()](beast::error_code ec, std::size_t n) {
      self->drained_ += n;
      if (!ec && self->drained_ < Server::kDrainBytes) self->readDrain();
    });
  }

  beast::tcp_stream stream_;
  Server::Impl& server_;
  const ConnectionSlots::Id id_;
  asio::steady_timer timer_;
  beast::flat_buffer buffer_{Server::kMaxRequestBytes};
  http::request_parser<http::empty_body> parser_;
  bool head_only_ = false;
  std::function<bool()> fresh_;
  Clock::time_point asked_;
  std::string out_;
  std::array<char, 4096> scratch_{};
  std::size_t drained_ = 0;
};

}  // namespace

void MetricsHttpServer::Impl::admit(tcp::socket socket) {
  // Refused when every slot is busy answering: closed here, unanswered.
  admitConnection(slots, sessions, std::move(socket),
                  [this](tcp::socket s, auto id) { return std::make_shared<Session>(std::move(s), *this, id); });
}

MetricsHttpServer::MetricsHttpServer(const std::string& address, MetricsSource source, Limits limits)
    : impl_(std::make_unique<Impl>(std::move(source), limits)) {
  impl_->net.start(address, "metrics", [impl = impl_.get()](tcp::socket socket) { impl->admit(std::move(socket)); });
}

MetricsHttpServer::~MetricsHttpServer() { impl_->net.stop(); }

int MetricsHttpServer::port() const { return impl_->net.port(); }

}  // namespace sglc::server
