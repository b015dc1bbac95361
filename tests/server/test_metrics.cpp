// The Prometheus exposition (Metrics): counters, histograms, and gauges read off the request path.
#include <gtest/gtest.h>

#include <future>
#include <stdexcept>
#include <string>
#include <thread>

#include "metrics.hpp"

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

TEST(Metrics, GaugesAreReadByARefreshNeverByRender) {
  Metrics m;
  int reads = 0;
  m.gauge("g", "a gauge\nwith two lines", [&reads] {
    ++reads;
    return std::vector<Metrics::Sample>{{{{"map", "a\"b\\c\nd"}}, 2.5}};
  });
  m.gauge("broken", "throws", []() -> std::vector<Metrics::Sample> { throw std::runtime_error("loading"); });
  std::string text = m.render();
  EXPECT_EQ(reads, 0) << "a scrape never runs a reader";
  EXPECT_EQ(text.find("# TYPE g"), std::string::npos) << "no gauge before the first refresh";
  EXPECT_EQ(text.find(kGaugeAge), std::string::npos);
  m.refreshGauges();
  EXPECT_EQ(reads, 1);
  text = m.render();
  m.render();
  EXPECT_EQ(reads, 1);
  EXPECT_NE(text.find("# HELP g a gauge\\nwith two lines\n"), std::string::npos) << text;
  EXPECT_NE(text.find("g{map=\"a\\\"b\\\\c\\nd\"} 2.5\n"), std::string::npos) << text;
  EXPECT_EQ(text.find("broken"), std::string::npos) << "a gauge that cannot be read is left out";
  EXPECT_NE(text.find(std::string("# TYPE ") + kGaugeAge + " gauge\n" + kGaugeAge + " "), std::string::npos) << text;
}

TEST(Metrics, HooksRunOnceBeforeTheGaugesOfEachRefresh) {
  Metrics m;
  int snapshot = 0, seen = -1;
  m.beforeScrape([&] { ++snapshot; });
  m.beforeScrape([] { throw std::runtime_error("ignored"); });
  m.gauge("g", "x", [&] {
    seen = snapshot;
    return std::vector<Metrics::Sample>{{{}, 1.0}};
  });
  m.refreshGauges();
  EXPECT_EQ(snapshot, 1);
  EXPECT_EQ(seen, 1) << "the gauge reads after the hook";
  m.render();
  m.refreshGauges();
  EXPECT_EQ(snapshot, 2);
}

// A reader that does not return (a map database that does not answer) holds neither updates nor scrapes,
// which serve the values read before. (Were a lock held, this test would hang rather than pass.)
TEST(Metrics, ABlockedReaderHoldsNeitherUpdatesNorRendering) {
  Metrics m;
  m.counter("c_total", "x");
  std::promise<void> entered, release;
  const auto released = release.get_future().share();
  int reads = 0;  // written by the reader only; read after the refreshes have ended
  m.gauge("slow", "blocks on its second read", [&entered, released, &reads] {
    if (++reads == 2) {
      entered.set_value();
      released.wait();
    }
    return std::vector<Metrics::Sample>{{{}, static_cast<double>(reads)}};
  });
  m.refreshGauges();  // the first read returns at once
  std::thread refresh([&m] { m.refreshGauges(); });
  entered.get_future().wait();  // the second is blocked inside the refresh
  m.add("c_total", {{"code", "OK"}});
  const auto text = m.render();
  EXPECT_NE(text.find("c_total{code=\"OK\"} 1\n"), std::string::npos) << text;
  EXPECT_NE(text.find("\nslow 1\n"), std::string::npos) << "the values read before are served\n" << text;
  release.set_value();
  refresh.join();
  EXPECT_NE(m.render().find("\nslow 2\n"), std::string::npos);
}

TEST(Metrics, UndeclaredFamilyIsAProgrammingError) {
  Metrics m;
  m.counter("c", "x");
  EXPECT_THROW(m.add("nope", {}), std::logic_error);
  EXPECT_THROW(m.observe("c", {}, 1.0), std::logic_error);  // a counter is not a histogram
}

}  // namespace
}  // namespace sglc::server
