#include "metrics_http.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace sglc::server {
namespace {

using Clock = std::chrono::steady_clock;

// Splits "host:port" ("[::1]:9090" for IPv6); throws when there is no port.
std::pair<std::string, std::string> hostPort(const std::string& address) {
  const auto colon = address.rfind(':');
  if (colon == std::string::npos || colon + 1 == address.size())
    throw std::runtime_error("metrics address '" + address + "' is not host:port");
  const std::string port = address.substr(colon + 1);
  if (port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos || std::stoi(port) > 65535)
    throw std::runtime_error("metrics address '" + address + "': port must be a number 0..65535");
  std::string host = address.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  return {host, port};
}

int listenOn(const std::string& address, int& port) {
  const auto [host, service] = hostPort(address);
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* found = nullptr;
  if (const int rc = getaddrinfo(host.empty() ? nullptr : host.c_str(), service.c_str(), &hints, &found); rc != 0)
    throw std::runtime_error("metrics address '" + address + "': " + gai_strerror(rc));
  std::string why = "no address";
  int fd = -1;
  for (auto* a = found; a != nullptr && fd < 0; a = a->ai_next) {
    fd = socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol);
    if (fd < 0) continue;
    const int one = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (bind(fd, a->ai_addr, a->ai_addrlen) != 0 || listen(fd, 16) != 0) {
      why = std::strerror(errno);
      close(fd);
      fd = -1;
    }
  }
  freeaddrinfo(found);
  if (fd < 0) throw std::runtime_error("cannot serve metrics on " + address + ": " + why);
  sockaddr_storage bound{};
  socklen_t len = sizeof bound;
  getsockname(fd, reinterpret_cast<sockaddr*>(&bound), &len);
  port = ntohs(bound.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&bound)->sin6_port
                                           : reinterpret_cast<sockaddr_in*>(&bound)->sin_port);
  return fd;
}

// Reads the request head (up to the blank line) within the deadline. Returns "" on timeout, what came before
// the peer closed (no blank line then), and sets `too_large` when the head exceeds the limit.
std::string readHead(int fd, Clock::time_point deadline, bool& too_large) {
  std::string head;
  char buffer[1024];
  while (head.find("\r\n\r\n") == std::string::npos) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    pollfd p{fd, POLLIN, 0};
    if (left <= 0 || poll(&p, 1, static_cast<int>(left)) <= 0) return "";
    const ssize_t n = recv(fd, buffer, sizeof buffer, 0);
    if (n <= 0) return head;  // closed: whatever came (an incomplete request is answered 400)
    head.append(buffer, static_cast<std::size_t>(n));
    if (head.size() > MetricsHttpServer::kMaxRequestBytes) {
      too_large = true;
      return head;
    }
  }
  return head;
}

void sendAll(int fd, const std::string& data, Clock::time_point deadline) {
  std::size_t sent = 0;
  while (sent < data.size()) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    pollfd p{fd, POLLOUT, 0};
    if (left <= 0 || poll(&p, 1, static_cast<int>(left)) <= 0) return;
    const ssize_t n = send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return;
    sent += static_cast<std::size_t>(n);
  }
}

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

MetricsHttpServer::MetricsHttpServer(const std::string& address, std::function<std::string()> render)
    : render_(std::move(render)) {
  listen_fd_ = listenOn(address, port_);
  if (pipe2(wake_, O_CLOEXEC) != 0) {
    close(listen_fd_);
    throw std::runtime_error(std::string("metrics: pipe: ") + std::strerror(errno));
  }
  thread_ = std::thread([this] { serve(); });
}

MetricsHttpServer::~MetricsHttpServer() {
  const char stop = 1;
  (void)!write(wake_[1], &stop, 1);
  thread_.join();
  close(listen_fd_);
  close(wake_[0]);
  close(wake_[1]);
}

void MetricsHttpServer::serve() {
  for (;;) {
    pollfd fds[2] = {{listen_fd_, POLLIN, 0}, {wake_[0], POLLIN, 0}};
    if (poll(fds, 2, -1) < 0) {
      // EINTR, or a transient failure: wait a little (still woken by stop) instead of spinning or giving up.
      poll(&fds[1], 1, 100);
      continue;
    }
    if (fds[1].revents != 0) return;
    const int fd = accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) {
      // Out of descriptors (EMFILE/ENFILE) leaves the connection queued and poll ready at once: back off.
      if (errno != EINTR && errno != EAGAIN && errno != ECONNABORTED) poll(&fds[1], 1, 100);
      continue;
    }
    answer(fd);
    close(fd);
  }
}

void MetricsHttpServer::answer(int fd) const {
  const auto deadline = Clock::now() + kRequestTimeout;
  bool too_large = false;
  const std::string head = readHead(fd, deadline, too_large);
  if (head.empty()) return;  // timed out or closed: nothing to answer
  if (too_large)
    return sendAll(fd, response(431, "Request Header Fields Too Large", "request too large\n", false), deadline);
  // Request line: METHOD SP TARGET SP HTTP/1.x
  const auto line_end = head.find("\r\n");
  const std::string line = head.substr(0, line_end);
  const auto sp1 = line.find(' '), sp2 = line.rfind(' ');
  if (head.find("\r\n\r\n") == std::string::npos || sp1 == std::string::npos || sp2 <= sp1 ||
      line.compare(sp2 + 1, 7, "HTTP/1.") != 0)
    return sendAll(fd, response(400, "Bad Request", "malformed request (HTTP/1.x, lines end in CRLF)\n", false),
                   deadline);
  const std::string method = line.substr(0, sp1), target = line.substr(sp1 + 1, sp2 - sp1 - 1);
  const bool head_only = method == "HEAD";
  if (method != "GET" && !head_only)
    return sendAll(fd, response(405, "Method Not Allowed", "only GET and HEAD\n", false), deadline);
  const std::string path = target.substr(0, target.find('?'));
  if (path != "/metrics") return sendAll(fd, response(404, "Not Found", "see /metrics\n", head_only), deadline);
  const std::string body = render_();  // the send gets its own time: a slow render must not void the answer
  sendAll(fd, response(200, "OK", body, head_only, "text/plain; version=0.0.4; charset=utf-8"),
          Clock::now() + kRequestTimeout);
}

}  // namespace sglc::server
