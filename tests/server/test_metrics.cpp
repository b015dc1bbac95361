// The Prometheus exposition (Metrics) and its HTTP endpoint (MetricsHttpServer) on a loopback socket.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <stdexcept>
#include <string>

#include "metrics.hpp"
#include "metrics_http.hpp"

namespace sglc::server {
namespace {

TEST(Metrics, CountersAndHistogramsInTheTextFormat) {
  Metrics m;
  m.counter("t_total", "calls");
  m.histogram("t_seconds", "time");
  m.add("t_total", {{"code", "OK"}});
  m.add("t_total", {{"code", "OK"}}, 2);
  m.add("t_total", {{"code", "NOT_FOUND"}});
  m.observe("t_seconds", {{"stage", "a"}}, 0.003);   // bucket le=0.005
  m.observe("t_seconds", {{"stage", "a"}}, 0.0005);  // le=0.001
  m.observe("t_seconds", {{"stage", "a"}}, 60.0);    // only +Inf
  const std::string text = m.render();
  EXPECT_NE(text.find("# HELP t_total calls\n# TYPE t_total counter\n"), std::string::npos) << text;
  EXPECT_NE(text.find("t_total{code=\"OK\"} 3\n"), std::string::npos) << text;
  EXPECT_NE(text.find("t_total{code=\"NOT_FOUND\"} 1\n"), std::string::npos);
  EXPECT_NE(text.find("# TYPE t_seconds histogram\n"), std::string::npos);
  // Buckets are cumulative.
  EXPECT_NE(text.find("t_seconds_bucket{stage=\"a\",le=\"0.001\"} 1\n"), std::string::npos) << text;
  EXPECT_NE(text.find("t_seconds_bucket{stage=\"a\",le=\"0.0025\"} 1\n"), std::string::npos);
  EXPECT_NE(text.find("t_seconds_bucket{stage=\"a\",le=\"0.005\"} 2\n"), std::string::npos);
  EXPECT_NE(text.find("t_seconds_bucket{stage=\"a\",le=\"10\"} 2\n"), std::string::npos);
  EXPECT_NE(text.find("t_seconds_bucket{stage=\"a\",le=\"+Inf\"} 3\n"), std::string::npos);
  EXPECT_NE(text.find("t_seconds_sum{stage=\"a\"} 60.0035\n"), std::string::npos) << text;
  EXPECT_NE(text.find("t_seconds_count{stage=\"a\"} 3\n"), std::string::npos);
}

TEST(Metrics, LabelValuesAreEscapedAndGaugesReadAtScrape) {
  Metrics m;
  int reads = 0;
  m.gauge("g", "a gauge\nwith two lines", [&reads] {
    ++reads;
    return std::vector<Metrics::Sample>{{{{"map", "a\"b\\c\nd"}}, 2.5}};
  });
  m.gauge("broken", "throws", []() -> std::vector<Metrics::Sample> { throw std::runtime_error("loading"); });
  const std::string text = m.render();
  EXPECT_EQ(reads, 1);
  EXPECT_NE(text.find("# HELP g a gauge\\nwith two lines\n"), std::string::npos) << text;
  EXPECT_NE(text.find("g{map=\"a\\\"b\\\\c\\nd\"} 2.5\n"), std::string::npos) << text;
  EXPECT_EQ(text.find("broken"), std::string::npos) << "a gauge that cannot be read is left out";
  m.render();
  EXPECT_EQ(reads, 2);
}

TEST(Metrics, HooksRunOnceBeforeTheGaugesOfEachScrape) {
  Metrics m;
  int snapshot = 0, seen = -1;
  m.beforeScrape([&] { ++snapshot; });
  m.beforeScrape([] { throw std::runtime_error("ignored"); });
  m.gauge("g", "x", [&] {
    seen = snapshot;
    return std::vector<Metrics::Sample>{{{}, 1.0}};
  });
  m.render();
  EXPECT_EQ(snapshot, 1);
  EXPECT_EQ(seen, 1) << "the gauge reads after the hook";
  m.render();
  EXPECT_EQ(snapshot, 2);
}

TEST(Metrics, UndeclaredFamilyIsAProgrammingError) {
  Metrics m;
  m.counter("c", "x");
  EXPECT_THROW(m.add("nope", {}), std::logic_error);
  EXPECT_THROW(m.observe("c", {}, 1.0), std::logic_error);  // a counter is not a histogram
}

// Sends `request` to 127.0.0.1:port and returns everything the server answers until it closes.
std::string exchange(int port, const std::string& request) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    close(fd);
    return "connect failed";
  }
  std::size_t sent = 0;
  while (sent < request.size()) {
    const ssize_t n = send(fd, request.data() + sent, request.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) break;
    sent += static_cast<std::size_t>(n);
  }
  shutdown(fd, SHUT_WR);  // the request is complete
  std::string out;
  char buffer[4096];
  for (ssize_t n; (n = recv(fd, buffer, sizeof buffer, 0)) > 0;) out.append(buffer, static_cast<std::size_t>(n));
  close(fd);
  return out;
}

TEST(MetricsHttp, ServesMetricsAndRefusesTheRest) {
  MetricsHttpServer http("127.0.0.1:0", [] { return std::string("x_total 7\n"); });
  ASSERT_GT(http.port(), 0);
  const auto ok = exchange(http.port(), "GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n");
  EXPECT_EQ(ok.rfind("HTTP/1.1 200 OK\r\n", 0), 0u) << ok;
  EXPECT_NE(ok.find("Content-Type: text/plain; version=0.0.4"), std::string::npos);
  EXPECT_NE(ok.find("Content-Length: 10\r\n"), std::string::npos);
  EXPECT_EQ(ok.substr(ok.size() - 10), "x_total 7\n");
  const auto head = exchange(http.port(), "HEAD /metrics?x=1 HTTP/1.0\r\n\r\n");
  EXPECT_EQ(head.rfind("HTTP/1.1 200 OK\r\n", 0), 0u);
  EXPECT_EQ(head.find("x_total"), std::string::npos) << "HEAD has no body";
  EXPECT_EQ(exchange(http.port(), "GET / HTTP/1.1\r\n\r\n").rfind("HTTP/1.1 404", 0), 0u);
  EXPECT_EQ(exchange(http.port(), "POST /metrics HTTP/1.1\r\n\r\n").rfind("HTTP/1.1 405", 0), 0u);
  EXPECT_EQ(exchange(http.port(), "garbage\r\n\r\n").rfind("HTTP/1.1 400", 0), 0u);
  EXPECT_EQ(exchange(http.port(), "GET /metrics HTTP/1.1\n\n").rfind("HTTP/1.1 400", 0), 0u) << "LF only";
  EXPECT_EQ(exchange(http.port(), std::string("\xff\0\x01 binary", 10)).rfind("HTTP/1.1 400", 0), 0u);
  EXPECT_EQ(exchange(http.port(), "GET /metrics HTTP/1.1\r\nX: " + std::string(20000, 'a') + "\r\n\r\n")
                .rfind("HTTP/1.1 431", 0),
            0u);
  // A connection that closes without sending anything gets nothing, and the server goes on.
  EXPECT_EQ(exchange(http.port(), ""), "");
  EXPECT_EQ(exchange(http.port(), "GET /metrics HTTP/1.1\r\n\r\n").rfind("HTTP/1.1 200", 0), 0u);
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
