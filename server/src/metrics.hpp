// The server's metrics in the Prometheus text exposition format (version 0.0.4): counters and histograms the
// server updates as it works, and gauges read when scraped. Thread-safe; updates take one short lock.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace sglc::server {

// Label names and values of one series, in order (e.g. {{"method", "Ingest"}, {"code", "OK"}}).
using Labels = std::vector<std::pair<std::string, std::string>>;

// Histogram bucket upper bounds for durations in seconds: 1 ms .. 10 s.
inline constexpr std::array<double, 13> kSecondsBuckets = {0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1,
                                                           0.25,  0.5,    1.0,   2.5,  5.0,   10.0};

class Metrics {
 public:
  // One sample of a gauge family read at scrape time.
  struct Sample {
    Labels labels;
    double value = 0;
  };
  using GaugeReader = std::function<std::vector<Sample>()>;

  // Declares a family (once per name; later declarations of the same name are ignored).
  void counter(const std::string& name, const std::string& help);
  void histogram(const std::string& name, const std::string& help);
  // A gauge whose samples `read` gives at every scrape (it must not call back into this object). A reader
  // that throws leaves its family out of that scrape.
  void gauge(const std::string& name, const std::string& help, GaugeReader read);
  // Runs once at the start of every render(), before the gauges are read (e.g. to take one snapshot of the
  // database that several gauges share). A hook that throws is ignored for that scrape.
  void beforeScrape(std::function<void()> hook);

  // Updates; the family must have been declared (std::logic_error otherwise: a programming error).
  void add(const std::string& name, const Labels& labels, double amount = 1);
  void observe(const std::string& name, const Labels& labels, double seconds);

  // Every family, in name order, series in label order.
  std::string render() const;

 private:
  struct Histogram {
    std::array<std::uint64_t, kSecondsBuckets.size()> buckets{};  // non-cumulative counts
    std::uint64_t count = 0;
    double sum = 0;
  };
  struct Family {
    std::string help;
    enum class Type { kCounter, kHistogram, kGauge } type = Type::kCounter;
    std::map<Labels, double> counters;
    std::map<Labels, Histogram> histograms;
    GaugeReader read;
  };
  Family& family(const std::string& name, Family::Type type);

  mutable std::mutex mutex_;
  std::map<std::string, Family> families_;
  std::vector<std::function<void()>> hooks_;
};

// A label value escaped for the exposition format (backslash, double quote and line feed).
std::string escapeLabelValue(const std::string& value);

}  // namespace sglc::server
