// The metrics' HTTP endpoint (MetricsHttpServer) on loopback sockets: what it answers, and that idle, slow,
// garbage and oversized connections hold neither it nor a scrape.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "metrics_http.hpp"

namespace sglc::server {
namespace {

using namespace std::chrono_literals;

// A TCP connection to 127.0.0.1:port from the loopback address `from` (another 127.x address is another peer).
int connectTo(int port, const char* from = "127.0.0.1") {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in local{};
  local.sin_family = AF_INET;
  inet_pton(AF_INET, from, &local.sin_addr);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (bind(fd, reinterpret_cast<sockaddr*>(&local), sizeof local) != 0 ||
      connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    close(fd);
    throw std::runtime_error("cannot connect from " + std::string(from));
  }
  return fd;
}

void sendAll(int fd, const std::string& data) {
  std::size_t sent = 0;
  while (sent < data.size()) {
    const ssize_t n = send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) break;
    sent += static_cast<std::size_t>(n);
  }
}

// Everything the server sends on fd until it closes; `reset` says whether the connection ended in a reset.
std::string readToEnd(int fd, bool* reset = nullptr) {
  std::string out;
  char buffer[4096];
  ssize_t n = 0;
  while ((n = recv(fd, buffer, sizeof buffer, 0)) > 0) out.append(buffer, static_cast<std::size_t>(n));
  if (reset) *reset = n < 0 && errno == ECONNRESET;
  return out;
}

// Sends `request`, ends the sending side, and returns the answer.
std::string exchange(int port, const std::string& request, const char* from = "127.0.0.1") {
  const int fd = connectTo(port, from);
  sendAll(fd, request);
  shutdown(fd, SHUT_WR);  // the request is complete
  auto out = readToEnd(fd);
  close(fd);
  return out;
}

// Whether the server still holds fd open: nothing to read, not closed (waits for nothing).
bool stillOpen(int fd) {
  char c = 0;
  const ssize_t n = recv(fd, &c, 1, MSG_DONTWAIT);
  return n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK);
}

// Whether the server closed fd (or reset it), waiting up to a minute.
bool closedByServer(int fd) {
  pollfd p{fd, POLLIN, 0};
  if (poll(&p, 1, 60'000) <= 0) return false;
  char c = 0;
  return recv(fd, &c, 1, 0) <= 0;
}

const std::string kScrape = "GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n";

TEST(MetricsHttp, ServesMetricsAndRefusesTheRest) {
  MetricsHttpServer http("127.0.0.1:0", [] { return std::string("x_total 7\n"); });
  ASSERT_GT(http.port(), 0);
  const auto ok = exchange(http.port(), kScrape);
  EXPECT_EQ(ok.rfind("HTTP/1.1 200 OK\r\n", 0), 0u) << ok;
  EXPECT_NE(ok.find("Content-Type: text/plain; version=0.0.4"), std::string::npos);
  EXPECT_NE(ok.find("Content-Length: 10\r\n"), std::string::npos);
  EXPECT_EQ(ok.substr(ok.size() - 10), "x_total 7\n");
  const auto head = exchange(http.port(), "HEAD /metrics?x=1 HTTP/1.0\r\n\r\n");
  EXPECT_EQ(head.rfind("HTTP/1.1 200 OK\r\n", 0), 0u);
  EXPECT_NE(head.find("Content-Length: 10\r\n"), std::string::npos);
  EXPECT_EQ(head.find("x_total"), std::string::npos) << "HEAD has no body";
  EXPECT_EQ(exchange(http.port(), "GET / HTTP/1.1\r\n\r\n").rfind("HTTP/1.1 404", 0), 0u);
  EXPECT_EQ(exchange(http.port(), "POST /metrics HTTP/1.1\r\n\r\n").rfind("HTTP/1.1 405", 0), 0u);
  EXPECT_EQ(exchange(http.port(), "garbage\r\n\r\n").rfind("HTTP/1.1 400", 0), 0u);
  EXPECT_EQ(exchange(http.port(), "GET /metrics HTTP/1.1\n\n").rfind("HTTP/1.1 400", 0), 0u) << "LF only";
  EXPECT_EQ(exchange(http.port(), "GET /metrics HTTP/1.1\r\nHost: x\r\n").rfind("HTTP/1.1 400", 0), 0u) << "incomplete";
  EXPECT_EQ(exchange(http.port(), std::string("\xff\0\x01 binary", 10)).rfind("HTTP/1.1 400", 0), 0u);
  // The start of a TLS ClientHello (record type 22, version 3.1).
  EXPECT_EQ(
      exchange(http.port(), std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", 11)).rfind("HTTP/1.1 400", 0),
      0u);
  EXPECT_EQ(exchange(http.port(), "GET /metrics HTTP/1.1\r\nX: " + std::string(20000, 'a') + "\r\n\r\n")
                .rfind("HTTP/1.1 431", 0),
            0u);
  // A connection that closes without sending anything gets nothing, and the server goes on.
  EXPECT_EQ(exchange(http.port(), ""), "");
  EXPECT_EQ(exchange(http.port(), kScrape).rfind("HTTP/1.1 200", 0), 0u);
}

// A client that goes on sending a head far over the limit gets its 431 and an orderly end, not a reset that
// can destroy the answer before it is read.
TEST(MetricsHttp, AnOversizedHeadGets431AndAnOrderlyClose) {
  MetricsHttpServer http("127.0.0.1:0", [] { return std::string("x 1\n"); });
  const int fd = connectTo(http.port());
  sendAll(fd, "GET /metrics HTTP/1.1\r\nX: " + std::string(200'000, 'a'));  // never ends the head
  bool reset = true;
  const auto answer = readToEnd(fd, &reset);
  close(fd);
  EXPECT_EQ(answer.rfind("HTTP/1.1 431 Request Header Fields Too Large\r\n", 0), 0u) << answer.substr(0, 200);
  EXPECT_FALSE(reset) << "the connection was reset";
}

// Idle, half-sent and garbage connections, held open, do not delay a scrape: it is answered while they are all
// still open (each has a minute to send its request here, so none is closed before the scrape ends).
TEST(MetricsHttp, IdleAndSlowConnectionsDoNotHoldAScrape) {
  MetricsHttpLimits limits;
  limits.request_timeout = 60s;
  MetricsHttpServer http("127.0.0.1:0", MetricsSource{[] { return std::string("x 1\n"); }, {}}, limits);
  std::vector<int> held;
  for (int i = 0; i < 10; ++i) held.push_back(connectTo(http.port()));  // idle
  for (int i = 0; i < 4; ++i) {                                         // a slow sender's first bytes
    held.push_back(connectTo(http.port(), "127.0.0.2"));
    sendAll(held.back(), "GET /metrics HTTP/1.1\r\nHost: x");
  }
  const int hello = connectTo(http.port(), "127.0.0.3");  // TLS to a plain-HTTP port, still open
  sendAll(hello, std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", 11));
  const auto answer = exchange(http.port(), kScrape, "127.0.0.4");
  EXPECT_EQ(answer.rfind("HTTP/1.1 200 OK\r\n", 0), 0u) << answer;
  for (const int fd : held) EXPECT_TRUE(stillOpen(fd)) << "a held connection was closed before the scrape ended";
  EXPECT_EQ(readToEnd(hello).rfind("HTTP/1.1 400", 0), 0u) << "garbage is answered at once, not held";
  close(hello);
  for (const int fd : held) close(fd);
}

// Over the per-peer or the total limit, the oldest connection still waiting for its request gives its slot to
// the newcomer: many idle connections, from one address or from many, cannot keep a scrape out.
TEST(MetricsHttp, ANewcomerTakesTheSlotOfTheOldestIdleConnection) {
  MetricsHttpLimits limits;
  limits.request_timeout = 60s;
  limits.max_per_peer = 3;
  limits.max_connections = 5;
  MetricsHttpServer http("127.0.0.1:0", MetricsSource{[] { return std::string("x 1\n"); }, {}}, limits);
  std::vector<int> one_peer;
  for (int i = 0; i < 4; ++i) one_peer.push_back(connectTo(http.port()));
  EXPECT_TRUE(closedByServer(one_peer[0])) << "the peer's fourth connection takes its oldest one's slot";
  for (int i = 1; i < 4; ++i) EXPECT_TRUE(stillOpen(one_peer[i]));
  const int b = connectTo(http.port(), "127.0.0.2"), c = connectTo(http.port(), "127.0.0.3");  // five in all
  EXPECT_EQ(exchange(http.port(), kScrape, "127.0.0.4").rfind("HTTP/1.1 200", 0), 0u)
      << "a full server serves a scrape";
  EXPECT_TRUE(closedByServer(one_peer[1])) << "in the oldest idle connection's slot";
  for (const int fd : {one_peer[2], one_peer[3], b, c}) EXPECT_TRUE(stillOpen(fd));
  for (const int fd : one_peer) close(fd);
  close(b);
  close(c);
}

// Only when every slot is busy answering is a newcomer refused (closed at once, unanswered).
TEST(MetricsHttp, ANewcomerIsRefusedWhenEverySlotIsBusyAnswering) {
  std::atomic<int> asked{0};
  std::atomic<bool> release{false};
  MetricsHttpLimits limits;
  limits.max_connections = 2;
  limits.fresh_wait = 60s;  // the two scrapes below wait (busy answering) until the test releases them
  MetricsHttpServer http("127.0.0.1:0",
                         MetricsSource{[] { return std::string("x 1\n"); },
                                       [&] {
                                         ++asked;
                                         return std::function<bool()>([&release] { return release.load(); });
                                       }},
                         limits);
  std::vector<int> scrapes;
  for (const char* from : {"127.0.0.1", "127.0.0.2"}) {
    scrapes.push_back(connectTo(http.port(), from));
    sendAll(scrapes.back(), kScrape);
  }
  for (int i = 0; i < 6000 && asked.load() < 2; ++i) std::this_thread::sleep_for(10ms);
  ASSERT_EQ(asked.load(), 2) << "both requests are being answered";
  const int third = connectTo(http.port(), "127.0.0.3");
  EXPECT_TRUE(closedByServer(third));
  close(third);
  release = true;
  for (const int fd : scrapes) {
    EXPECT_EQ(readToEnd(fd).rfind("HTTP/1.1 200", 0), 0u);
    close(fd);
  }
}

// A scrape asks for fresh gauges and is answered with them once they are there; when they do not come, it is
// answered after a bounded wait with what there is.
TEST(MetricsHttp, AScrapeWaitsForFreshGaugesABoundedTime) {
  std::atomic<int> asked{0}, rendered{0};
  MetricsHttpLimits limits;
  limits.fresh_wait = 200ms;
  MetricsHttpServer never("127.0.0.1:0",
                          MetricsSource{[&rendered] {
                                          ++rendered;
                                          return std::string("x 1\n");
                                        },
                                        [&asked] {
                                          ++asked;
                                          return std::function<bool()>([] { return false; });
                                        }},
                          limits);
  EXPECT_EQ(exchange(never.port(), kScrape).rfind("HTTP/1.1 200", 0), 0u) << "answered though never fresh";
  EXPECT_EQ(asked.load(), 1);
  EXPECT_EQ(rendered.load(), 1);
  EXPECT_EQ(exchange(never.port(), "GET /nope HTTP/1.1\r\n\r\n").rfind("HTTP/1.1 404", 0), 0u);
  EXPECT_EQ(asked.load(), 1) << "only a scrape asks for a refresh";

  // Values that become fresh a little later (another thread reads them) are the ones served.
  std::atomic<int> value{1};
  std::atomic<bool> ready{false};
  std::thread reader;
  limits.fresh_wait = 60s;
  MetricsHttpServer later("127.0.0.1:0",
                          MetricsSource{[&value] { return "x " + std::to_string(value.load()) + "\n"; },
                                        [&] {
                                          reader = std::thread([&] {
                                            std::this_thread::sleep_for(50ms);
                                            value = 2;
                                            ready = true;
                                          });
                                          return std::function<bool()>([&ready] { return ready.load(); });
                                        }},
                          limits);
  const auto answer = exchange(later.port(), kScrape);
  reader.join();
  EXPECT_EQ(answer.substr(answer.size() - 4), "x 2\n") << answer;
}

TEST(MetricsHttp, BadAddressesAreNamed) {
  try {
    MetricsHttpServer http("no-port", [] { return std::string(); });
    FAIL() << "no port accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no-port"), std::string::npos) << e.what();
  }
  for (const char* bad : {"127.0.0.1:70000", "127.0.0.1:-1", "127.0.0.1:9x"}) {
    EXPECT_THROW(MetricsHttpServer(bad, [] { return std::string(); }), std::runtime_error) << bad;
  }
  MetricsHttpServer first("127.0.0.1:0", [] { return std::string(); });
  try {
    MetricsHttpServer second("127.0.0.1:" + std::to_string(first.port()), [] { return std::string(); });
    FAIL() << "a port in use accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot serve metrics on 127.0.0.1:"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace sglc::server
