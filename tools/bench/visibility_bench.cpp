// sglc-bench-visibility: how soon a scan one server acknowledged is found by queries on another server of the
// same database (replicas on PostgreSQL). Scan i is ingested through server i mod n; then server (i + 1) mod n
// is queried with the same cloud (scoped to the probe's session, rejected candidates included) until the new
// scan is among the candidates. Prints one JSON object: the latency from the acknowledgement to the send of
// the first query that found the scan (p50, p99, max), and what one query takes (the probe's resolution).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "sglc/client/client.hpp"
#include "sglc/io.hpp"
#include "sglc/sequence.hpp"

namespace {

using Clock = std::chrono::steady_clock;
namespace sc = sglc::client;

double ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size()))) - 1;
  return v[std::min(i, v.size() - 1)];
}

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string part; std::getline(in, part, ',');)
    if (!part.empty()) out.push_back(part);
  return out;
}

bool found(const sglc::v1::QueryResponse& r, std::int64_t id) {
  return std::any_of(r.candidates().begin(), r.candidates().end(), [&](const auto& c) { return c.scan_id() == id; });
}

// Ingests through one server, queries another until found; prints the JSON object. 0 when every scan was found.
int probe(const std::vector<std::string>& addresses, const std::string& dir, const std::string& map,
          const std::string& session, int scans, double timeout_s) {
  const auto seq = sglc::openSequence(dir);
  if (seq.frames.empty()) throw std::runtime_error(dir + ": the sequence has no scans");
  std::vector<sc::Client> clients;
  for (const auto& a : addresses) clients.push_back(sc::Client::connect(a));
  clients[0].ensureMap(map);
  sglc::v1::QueryOptions q;
  q.set_scope(sglc::v1::SCOPE_SESSIONS);
  q.add_sessions("probe/" + session);
  q.set_include_rejected(true);
  q.set_refine(false);
  q.set_refine_set(true);
  q.set_candidates(20);
  q.set_top_k(20);
  std::vector<double> latency, query_ms;
  int lost = 0;
  for (int i = 0; i < scans; ++i) {
    const auto& f = seq.frames[static_cast<std::size_t>(i) % seq.frames.size()];
    const auto scan = sglc::readScan(f.scan_path, f.label_path);
    auto& writer = clients[static_cast<std::size_t>(i) % clients.size()];
    auto& reader = clients[static_cast<std::size_t>(i + 1) % clients.size()];
    const auto id = writer.ingest(sc::makeKey(map, "probe", session, i), scan).scan_id();
    const auto acked = Clock::now();
    bool seen = false;
    while (!seen && ms(Clock::now() - acked) < timeout_s * 1000) {
      const auto sent = Clock::now();
      const auto r = reader.queryScan(map, scan, q);
      query_ms.push_back(ms(Clock::now() - sent));
      if (found(r, id)) {
        latency.push_back(std::max(0.0, ms(sent - acked)));
        seen = true;
      }
    }
    lost += seen ? 0 : 1;
  }
  nlohmann::ordered_json out;
  out["servers"] = addresses.size();
  out["scans"] = scans;
  out["not_found_within_timeout"] = lost;
  out["visibility_ms"] = {{"p50", percentile(latency, 0.5)},
                          {"p99", percentile(latency, 0.99)},
                          {"max", latency.empty() ? 0.0 : *std::max_element(latency.begin(), latency.end())}};
  out["query_ms_median"] = percentile(query_ms, 0.5);
  std::cout << out.dump() << std::endl;
  return lost == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Cross-server visibility of acknowledged scans (replicas on one database)"};
  std::string servers, dir, map = "visibility", session = "probe";
  int scans = 100;
  double timeout_s = 30;
  app.add_option("--servers", servers, "Comma-separated host:port of the servers (at least 2)")->required();
  app.add_option("--seq", dir, "Sequence directory whose scans are ingested")->required();
  app.add_option("--map", map, "Map (created if missing)")->capture_default_str();
  app.add_option("--session", session, "Session of robot 'probe' (must be new)")->capture_default_str();
  app.add_option("--scans", scans, "Scans to probe")->capture_default_str()->check(CLI::Range(1, 100000));
  app.add_option("--timeout", timeout_s, "Give up on a scan after this long (s)")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  const auto addresses = split(servers);
  if (addresses.size() < 2) {
    std::cerr << "sglc-bench-visibility: --servers needs at least two addresses\n";
    return 2;
  }
  try {
    return probe(addresses, dir, map, session, scans, timeout_s);
  } catch (const std::exception& e) {  // an unreachable server, an unreadable scan: one clear line
    std::cerr << "sglc-bench-visibility: error: " << e.what() << "\n";
    return 1;
  }
}
