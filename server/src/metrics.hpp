// The server's metrics in the Prometheus text exposition format (version 0.0.4): counters and histograms the
// server updates as it works, and gauges read off the request path (refreshGauges, run by a GaugeRefresher).
// Thread-safe; updates take one short lock, and rendering holds it only to copy the current values.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace sglc::server {

// Label names and values of one series, in order (e.g. {{"method", "Ingest"}, {"code", "OK"}}). Values must
// come from a closed set (method names the server serves, status codes, stages, map names): every distinct
// set is a series kept for the life of the process.
using Labels = std::vector<std::pair<std::string, std::string>>;

// Histogram bucket upper bounds for durations in seconds: 1 ms .. 10 s.
inline constexpr std::array<double, 13> kSecondsBuckets = {0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1,
                                                           0.25,  0.5,    1.0,   2.5,  5.0,   10.0};

// The family that says how old the gauges in an exposition are.
inline constexpr const char* kGaugeAge = "sglc_metrics_read_age_seconds";

class Metrics {
 public:
  // One sample of a gauge family.
  struct Sample {
    Labels labels;
    double value = 0;
  };
  using GaugeReader = std::function<std::vector<Sample>()>;

  // Declares a family (once per name; later declarations of the same name are ignored).
  void counter(const std::string& name, const std::string& help);
  void histogram(const std::string& name, const std::string& help);
  // A gauge whose samples `read` gives at every refreshGauges() (it must not call back into this object). A
  // reader that throws leaves its family out until a later refresh reads it.
  void gauge(const std::string& name, const std::string& help, GaugeReader read);
  // Runs once at the start of every refreshGauges(), before the gauges are read (e.g. to take one snapshot of
  // the database that several gauges share). A hook that throws is ignored for that refresh.
  void beforeScrape(std::function<void()> hook);

  // Updates; the family must have been declared (std::logic_error otherwise: a programming error).
  void add(const std::string& name, const Labels& labels, double amount = 1);
  void observe(const std::string& name, const Labels& labels, double seconds);

  // Reads every gauge and keeps the values for render(). Readers may be slow or block (a database that does
  // not answer): call it from a thread of its own, never on a request path. Calls are serialised.
  void refreshGauges();

  // Every family, in name order, series in label order; gauges as the newest refreshGauges() read them (none
  // before the first), with kGaugeAge saying how long ago that was.
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
  struct GaugeValues {
    std::chrono::steady_clock::time_point read_at;
    std::map<std::string, std::vector<Sample>> samples;  // by family name
  };
  Family& family(const std::string& name, Family::Type type);

  mutable std::mutex mutex_;
  std::map<std::string, Family> families_;
  std::vector<std::function<void()>> hooks_;
  std::shared_ptr<const GaugeValues> gauges_;  // replaced whole by each refresh
  std::mutex refresh_mutex_;                   // one refresh at a time
};

// A label value escaped for the exposition format (backslash, double quote and line feed).
std::string escapeLabelValue(const std::string& value);

}  // namespace sglc::server
