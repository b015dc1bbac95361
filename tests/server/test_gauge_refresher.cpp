// GaugeRefresher: gauges are read on its thread when asked, and a request is answered by a refresh that
// started after it.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <future>
#include <thread>

#include "gauge_refresher.hpp"

namespace sglc::server {
namespace {

using namespace std::chrono_literals;

// Waits (up to a minute) for `done`.
bool eventually(const std::function<bool()>& done) {
  for (int i = 0; i < 6000; ++i) {
    if (done()) return true;
    std::this_thread::sleep_for(10ms);
  }
  return done();
}

TEST(GaugeRefresher, ReadsAtStartAndWhenAsked) {
  Metrics m;
  std::atomic<int> reads{0};
  m.gauge("g", "x", [&reads] { return std::vector<Metrics::Sample>{{{}, static_cast<double>(++reads)}}; });
  GaugeRefresher refresher(m);
  ASSERT_TRUE(eventually([&] { return m.render().find("\ng 1\n") != std::string::npos; })) << m.render();
  const auto fresh = refresher.request();
  ASSERT_TRUE(eventually(fresh));
  EXPECT_EQ(reads.load(), 2) << "one read at start, one for the request";
  EXPECT_NE(m.render().find("\ng 2\n"), std::string::npos) << m.render();
}

// A request made while a refresh is reading is not answered by that refresh (its values may predate the
// request), but by the next one.
TEST(GaugeRefresher, ARequestDuringARefreshWaitsForTheNextOne) {
  Metrics m;
  std::promise<void> entered, release;
  const auto released = release.get_future().share();
  std::atomic<int> reads{0};
  m.gauge("g", "x", [&entered, released, &reads] {
    if (++reads == 1) {  // the refresher's first read blocks until released
      entered.set_value();
      released.wait();
    }
    return std::vector<Metrics::Sample>{{{}, static_cast<double>(reads.load())}};
  });
  GaugeRefresher refresher(m);
  entered.get_future().wait();
  const auto fresh = refresher.request();
  EXPECT_FALSE(fresh());
  release.set_value();
  ASSERT_TRUE(eventually(fresh));
  EXPECT_EQ(reads.load(), 2) << "answered by a second read";
  EXPECT_NE(m.render().find("\ng 2\n"), std::string::npos) << m.render();
}

// Back-to-back requests (a flood of scrapes) get one refresh each, started at least kMinInterval apart.
TEST(GaugeRefresher, RefreshesStartAtLeastTheMinimumIntervalApart) {
  Metrics m;
  std::atomic<int> reads{0};
  m.gauge("g", "x", [&reads] { return std::vector<Metrics::Sample>{{{}, static_cast<double>(++reads)}}; });
  GaugeRefresher refresher(m);
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < 6; ++i) ASSERT_TRUE(eventually(refresher.request()));
  const auto elapsed = std::chrono::steady_clock::now() - start;
  // The first request may be served by the first refresh, if that had not started reading yet; the last five
  // each waited for a refresh that started at least kMinInterval after the one before.
  const int n = reads.load();
  EXPECT_TRUE(n == 6 || n == 7) << n;
  EXPECT_GE(elapsed, 5 * GaugeRefresher::kMinInterval - 20ms);
}

}  // namespace
}  // namespace sglc::server
