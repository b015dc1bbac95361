#include "metrics.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace sglc::server {
namespace {

// Numbers as Prometheus reads them: integers without a fraction, others with enough digits, +Inf/NaN spelt out.
std::string number(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
  if (v == std::floor(v) && std::fabs(v) < 1e15) return std::to_string(static_cast<long long>(v));
  for (int digits = 15;; ++digits) {  // the shortest text that reads back as v (at most 17 digits)
    std::ostringstream out;
    out.precision(digits);
    out << v;
    if (digits == 17 || std::stod(out.str()) == v) return out.str();
  }
}

std::string labelText(const Labels& labels, const std::string& extra_name = "", const std::string& extra_value = "") {
  if (labels.empty() && extra_name.empty()) return "";
  std::string out = "{";
  bool first = true;
  auto one = [&](const std::string& k, const std::string& v) {
    if (!first) out += ',';
    first = false;
    out += k + "=\"" + escapeLabelValue(v) + '"';
  };
  for (const auto& [k, v] : labels) one(k, v);
  if (!extra_name.empty()) one(extra_name, extra_value);
  return out + "}";
}

// Backslash and line feed escaped (HELP text), and the double quote too (label values).
std::string escaped(const std::string& text, bool quote) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    if (c == '\\')
      out += "\\\\";
    else if (c == '\n')
      out += "\\n";
    else if (c == '"' && quote)
      out += "\\\"";
    else
      out += c;
  }
  return out;
}

std::string helpText(const std::string& help) { return escaped(help, false); }

}  // namespace

std::string escapeLabelValue(const std::string& value) { return escaped(value, true); }

Metrics::Family& Metrics::family(const std::string& name, Family::Type type) {
  auto it = families_.find(name);
  if (it == families_.end() || it->second.type != type)
    throw std::logic_error("metrics: no " + std::string(type == Family::Type::kCounter ? "counter" : "histogram") +
                           " named " + name);
  return it->second;
}

void Metrics::counter(const std::string& name, const std::string& help) {
  const std::lock_guard lock(mutex_);
  families_.try_emplace(name, Family{help, Family::Type::kCounter, {}, {}, {}});
}

void Metrics::histogram(const std::string& name, const std::string& help) {
  const std::lock_guard lock(mutex_);
  families_.try_emplace(name, Family{help, Family::Type::kHistogram, {}, {}, {}});
}

void Metrics::gauge(const std::string& name, const std::string& help, GaugeReader read) {
  const std::lock_guard lock(mutex_);
  families_.try_emplace(name, Family{help, Family::Type::kGauge, {}, {}, std::move(read)});
}

void Metrics::beforeScrape(std::function<void()> hook) {
  const std::lock_guard lock(mutex_);
  hooks_.push_back(std::move(hook));
}

void Metrics::add(const std::string& name, const Labels& labels, double amount) {
  const std::lock_guard lock(mutex_);
  family(name, Family::Type::kCounter).counters[labels] += amount;
}

void Metrics::observe(const std::string& name, const Labels& labels, double seconds) {
  const std::lock_guard lock(mutex_);
  auto& h = family(name, Family::Type::kHistogram).histograms[labels];
  std::size_t b = 0;
  while (b < kSecondsBuckets.size() && seconds > kSecondsBuckets[b]) ++b;
  if (b < kSecondsBuckets.size()) ++h.buckets[b];
  ++h.count;
  h.sum += seconds;
}

void Metrics::refreshGauges() {
  const std::lock_guard refresh(refresh_mutex_);
  std::vector<std::pair<std::string, GaugeReader>> readers;
  std::vector<std::function<void()>> hooks;
  {
    const std::lock_guard lock(mutex_);
    for (const auto& [name, f] : families_)
      if (f.type == Family::Type::kGauge) readers.emplace_back(name, f.read);
    hooks = hooks_;
  }
  for (const auto& hook : hooks) {
    try {
      hook();
    } catch (...) {
      // The gauges that depend on it fail on their own and are left out.
    }
  }
  auto values = std::make_shared<GaugeValues>();
  for (const auto& [name, read] : readers) {
    try {
      values->samples[name] = read();
    } catch (...) {
      // Left out (e.g. the map database is still loading).
    }
  }
  values->read_at = std::chrono::steady_clock::now();
  const std::lock_guard lock(mutex_);
  gauges_ = std::move(values);
}

std::string Metrics::render() const {
  // A copy of the values under the lock; the text is made outside it, so RPCs never wait for a scrape.
  std::map<std::string, Family> families;
  std::shared_ptr<const GaugeValues> gauges;
  {
    const std::lock_guard lock(mutex_);
    families = families_;
    gauges = gauges_;
  }
  std::string out;
  if (gauges) {
    const double age = std::chrono::duration<double>(std::chrono::steady_clock::now() - gauges->read_at).count();
    out += std::string("# HELP ") + kGaugeAge + " Seconds since the gauges in this exposition were read\n# TYPE " +
           kGaugeAge + " gauge\n" + kGaugeAge + ' ' + number(std::round(age * 1000) / 1000) + '\n';
  }
  for (const auto& [name, f] : families) {
    const std::vector<Sample>* samples = nullptr;
    if (f.type == Family::Type::kGauge) {
      if (!gauges || !gauges->samples.count(name)) continue;
      samples = &gauges->samples.at(name);
    }
    const char* type = f.type == Family::Type::kCounter     ? "counter"
                       : f.type == Family::Type::kHistogram ? "histogram"
                                                            : "gauge";
    out += "# HELP " + name + ' ' + helpText(f.help) + "\n# TYPE " + name + ' ' + type + '\n';
    if (f.type == Family::Type::kCounter)
      for (const auto& [labels, v] : f.counters) out += name + labelText(labels) + ' ' + number(v) + '\n';
    if (samples)
      for (const auto& s : *samples) out += name + labelText(s.labels) + ' ' + number(s.value) + '\n';
    if (f.type != Family::Type::kHistogram) continue;
    for (const auto& [labels, h] : f.histograms) {
      std::uint64_t cumulative = 0;
      for (std::size_t b = 0; b < kSecondsBuckets.size(); ++b) {
        cumulative += h.buckets[b];
        out += name + "_bucket" + labelText(labels, "le", number(kSecondsBuckets[b])) + ' ' +
               std::to_string(cumulative) + '\n';
      }
      out += name + "_bucket" + labelText(labels, "le", "+Inf") + ' ' + std::to_string(h.count) + '\n';
      out += name + "_sum" + labelText(labels) + ' ' + number(h.sum) + '\n';
      out += name + "_count" + labelText(labels) + ' ' + std::to_string(h.count) + '\n';
    }
  }
  return out;
}

}  // namespace sglc::server
