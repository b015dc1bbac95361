// sglc-bench: the service end to end over loopback, printed as one JSON object.
//
// Starts build/bin/sglc-server (next to this binary) on a scratch database, or uses --server ADDR, and feeds it
// simulated HDL-64 keyframes of the built-in route (about 115k points each), packed once before timing:
//   1. map:        robot "map" stores every 4th frame of the route (no queries).
//   2. round trip: robot "visitor" drives the frames half-way between them (2 frames, ~1.5 m, off the map's
//                  poses) with Ingest + query: top-5 candidates verified, verified ones refined. Latency is
//                  the client's wall time per call: p50 / p99.
//   3. throughput: 1, 4 and 16 robots at once (one thread each, synchronous Ingest + query) for --seconds
//                  each; keyframes/s = acknowledged scans / wall time.
//   4. memory:     scans are added (4 robots, no queries) until the map holds --rss-scans; then the server's
//                  resident memory (VmRSS) and peak (VmHWM) from /proc (only for a server started here).
//
//   build/bin/sglc-bench [--server ADDR] [--frames 120] [--seconds 20] [--robots 1,4,16] [--rss-scans 10000]
#include <unistd.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <thread>

#include "common/finite_options.hpp"
#include "server_process.hpp"
#include "sglc/client/client.hpp"
#include "sglc/elapsed.hpp"
#include "sglc/version.hpp"
#include "sim/simulator.hpp"

namespace {

namespace fs = std::filesystem;
using namespace sglc;
using bench::ServerProcess;
using nlohmann::ordered_json;

struct Keyframe {
  v1::IngestRequest request;  // packed scan; key and options are set per call
  std::size_t points = 0;
};

v1::IngestRequest requestFor(const Keyframe& kf, const std::string& map, const std::string& robot,
                             const std::string& session, std::int64_t seq, bool query) {
  v1::IngestRequest r = kf.request;
  *r.mutable_key() = client::makeKey(map, robot, session, seq);
  r.set_query(query);
  if (query) {
    auto* q = r.mutable_query_options();
    q->set_scope(v1::SCOPE_WHOLE_MAP);
    q->set_top_k(5);
    q->set_candidates(5);
    q->set_exclude_recent(10);
  }
  return r;
}

struct Options {
  std::string server_addr;
  std::string dir = (fs::temp_directory_path() / "sglc-bench").string();
  int frames = 120;
  double seconds = 20;
  std::vector<int> robot_counts{1, 4, 16};
  std::int64_t rss_scans = 10000;
};

void addOptions(CLI::App& app, Options& o) {
  app.add_option("--server", o.server_addr, "use this running server instead of starting one");
  app.add_option("--dir", o.dir, "scratch directory for a started server (removed first)")->capture_default_str();
  app.add_option("--frames", o.frames, "keyframes rendered for the map (and as many for the visitor)")
      ->capture_default_str()
      ->check(CLI::Range(8, 2000));
  app.add_option("--seconds", o.seconds, "duration of each throughput run")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 3600.0));
  app.add_option("--robots", o.robot_counts, "concurrent robots of the throughput runs")
      ->capture_default_str()
      ->delimiter(',');
  app.add_option("--rss-scans", o.rss_scans, "map size at which server memory is read (0: skip)")
      ->capture_default_str();
}

struct Keyframes {
  std::vector<Keyframe> map;      // every 4th frame of the route
  std::vector<Keyframe> visitor;  // the frames half-way between them
};

// Renders and packs the keyframes (before any timing): `frames` of each kind, at most what the route holds.
Keyframes renderKeyframes(int frames, ordered_json& out) {
  const auto route = sim::loopRoute();
  sim::SimConfig sc;
  sc.threads = 2;
  const sim::Simulator simulator(route, sc);
  const int stride = 4;
  frames = std::min(frames, (simulator.numFrames() - 3) / stride);
  Keyframes keyframes;
  std::size_t total_points = 0;
  const auto t_render = Clock::now();
  for (int i = 0; i < frames; ++i)
    for (int offset : {0, stride / 2}) {
      const auto frame = simulator.render(i * stride + offset);
      Keyframe kf;
      kf.request = client::makeIngestRequest(client::makeKey("", "", "", 0), frame.scan);
      kf.points = frame.scan.labels.size();
      total_points += kf.points;
      (offset == 0 ? keyframes.map : keyframes.visitor).push_back(std::move(kf));
    }
  out["keyframes"] = {{"source", route.source},
                      {"rendered", 2 * frames},
                      {"mean_points", static_cast<double>(total_points) / (2.0 * frames)},
                      {"render_s", msSince(t_render) / 1000.0}};
  return keyframes;
}

struct Server {
  std::unique_ptr<ServerProcess> process;  // none with --server
  std::string address;
};

// The --server address, or a sglc-server (next to this binary) started on a free port and a scratch database.
Server startServer(const Options& o) {
  Server server{nullptr, o.server_addr};
  if (server.address.empty()) {
    fs::remove_all(o.dir);
    fs::create_directories(o.dir);
    const auto binary = fs::canonical("/proc/self/exe").parent_path() / "sglc-server";
    server.address = "127.0.0.1:" + std::to_string(bench::freePort());
    server.process =
        std::make_unique<ServerProcess>(binary.string(), o.dir + "/bench.db", server.address, o.dir + "/server.log");
  }
  return server;
}

// Waits until the server serves (once its database is loaded); false, said on stderr, when it does not within
// a minute or a server started here exits.
bool waitUntilServing(const client::Client& cl, const Server& server) {
  const auto t_up = Clock::now();
  for (;;) {
    try {
      cl.listMaps();
      return true;
    } catch (const client::RpcError& e) {
      if (e.code() != grpc::StatusCode::UNAVAILABLE || msSince(t_up) > 60'000 ||
          (server.process && !server.process->alive())) {
        std::cerr << "sglc-bench: server at " << server.address << " not serving: " << e.what() << "\n";
        return false;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }
}

// The server's CPU time per keyframe over a stretch of work (process user + system time, so other work on the
// machine does not count), and its minor page faults per keyframe (memory touched afresh): added to `out` when
// sglc-bench started the server, left out otherwise.
class ServerCpu {
 public:
  explicit ServerCpu(pid_t pid) : pid_(pid), start_(pid > 0 ? bench::procCpuMs(pid) : bench::CpuMs{}) {}
  void report(ordered_json& out, std::size_t keyframes) const {
    if (pid_ <= 0 || keyframes == 0 || start_.user < 0) return;
    const auto now = bench::procCpuMs(pid_);
    if (now.user < 0) return;
    const auto per = [&](double a, double b) { return (a - b) / static_cast<double>(keyframes); };
    out["server_cpu_ms_per_keyframe"] = per(now.total(), start_.total());
    out["server_user_ms_per_keyframe"] = per(now.user, start_.user);
    out["server_sys_ms_per_keyframe"] = per(now.system, start_.system);
    out["server_minor_faults_per_keyframe"] = per(now.minor_faults, start_.minor_faults);
  }

 private:
  pid_t pid_;
  bench::CpuMs start_;
};

// 1. The map: robot "map" stores its keyframes, no queries.
ordered_json benchMapIngest(const client::Client& cl, const std::string& map, const std::vector<Keyframe>& frames,
                            pid_t server) {
  const ServerCpu cpu(server);
  const auto t0 = Clock::now();
  std::vector<double> lat;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const auto t1 = Clock::now();
    cl.ingest(requestFor(frames[i], map, "map", "run", static_cast<std::int64_t>(i), false));
    lat.push_back(msSince(t1));
  }
  ordered_json out = {{"scans", frames.size()},
                      {"p50_ms", percentile(lat, 0.5)},
                      {"p99_ms", percentile(lat, 0.99)},
                      {"keyframes_per_s", 1000.0 * static_cast<double>(frames.size()) / msSince(t0)}};
  cpu.report(out, frames.size());
  return out;
}

// 2. Round trip: robot "visitor" ingests and queries (top-5 verified, verified ones refined).
ordered_json benchRoundTrip(const client::Client& cl, const std::string& map, const std::vector<Keyframe>& frames,
                            pid_t server) {
  const ServerCpu cpu(server);
  std::vector<double> lat, server_total, fingerprint, search, verify, refine, store;
  std::size_t with_loop = 0, refined = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const auto t1 = Clock::now();
    const auto r = cl.ingest(requestFor(frames[i], map, "visitor", "run", static_cast<std::int64_t>(i), true));
    lat.push_back(msSince(t1));
    server_total.push_back(r.timing().total_ms());
    fingerprint.push_back(r.timing().fingerprint_ms());
    search.push_back(r.timing().search_ms());
    store.push_back(r.timing().store_ms());
    verify.push_back(r.timing().verify_ms());
    refine.push_back(r.timing().refine_ms());
    bool any = false;
    for (const auto& c : r.loops()) {
      any = any || c.verified();
      refined += c.refined();
    }
    with_loop += any;
  }
  ordered_json out = {{"scans", frames.size()},
                      {"top_k", 5},
                      {"p50_ms", percentile(lat, 0.5)},
                      {"p99_ms", percentile(lat, 0.99)},
                      {"server_total_p50_ms", percentile(server_total, 0.5)},
                      {"server_fingerprint_p50_ms", percentile(fingerprint, 0.5)},
                      {"server_search_p50_ms", percentile(search, 0.5)},
                      {"server_verify_p50_ms", percentile(verify, 0.5)},
                      {"server_refine_p50_ms", percentile(refine, 0.5)},
                      {"server_store_p50_ms", percentile(store, 0.5)},
                      {"queries_with_a_loop", with_loop},
                      {"refined_loops", refined}};
  cpu.report(out, frames.size());
  return out;
}

// 3. One throughput run: `n` robots at once (one thread each, synchronous Ingest + query) for `seconds`.
ordered_json benchThroughputRun(const client::Client& cl, const std::string& map, const Keyframes& keyframes, int n,
                                double seconds, pid_t server) {
  const ServerCpu cpu(server);
  std::atomic<std::int64_t> done{0}, failed{0};
  std::vector<std::vector<double>> lats(static_cast<std::size_t>(n));
  const auto deadline = Clock::now() + std::chrono::duration<double>(seconds);
  const auto t0 = Clock::now();
  std::vector<std::thread> threads;
  for (int r = 0; r < n; ++r)
    threads.emplace_back([&, r] {
      const std::string robot = "c" + std::to_string(n) + "-r" + std::to_string(r);
      const auto& frames_r = (r % 2 == 0) ? keyframes.visitor : keyframes.map;
      std::size_t i = static_cast<std::size_t>(r) * frames_r.size() / static_cast<std::size_t>(n);
      for (std::int64_t seq = 0; Clock::now() < deadline; ++seq, i = (i + 1) % frames_r.size()) {
        const auto t1 = Clock::now();
        try {
          cl.ingest(requestFor(frames_r[i], map, robot, "run", seq, true));
          lats[static_cast<std::size_t>(r)].push_back(msSince(t1));
          ++done;
        } catch (const std::exception& e) {
          if (failed++ == 0) std::cerr << "sglc-bench: " << e.what() << "\n";
        }
      }
    });
  for (auto& t : threads) t.join();
  const double wall = msSince(t0) / 1000.0;
  std::vector<double> all;
  for (const auto& l : lats) all.insert(all.end(), l.begin(), l.end());
  ordered_json out = {{"robots", n},
                      {"keyframes", done.load()},
                      {"failed", failed.load()},
                      {"seconds", wall},
                      {"keyframes_per_s", static_cast<double>(done) / wall},
                      {"p50_ms", percentile(all, 0.5)},
                      {"p99_ms", percentile(all, 0.99)}};
  // Failed calls cost server CPU without counting as keyframes: no per-keyframe figure then.
  if (failed.load() == 0) cpu.report(out, static_cast<std::size_t>(done.load()));
  return out;
}

// 4. Server memory: 4 robots add scans (no queries) until the map holds `rss_scans`.
ordered_json benchMemory(const client::Client& cl, const std::string& map, const std::vector<Keyframe>& frames,
                         std::int64_t rss_scans, const ServerProcess& server) {
  std::atomic<std::int64_t> next{cl.getStats(map).scans()};
  const auto t0 = Clock::now();
  std::vector<std::thread> threads;
  for (int r = 0; r < 4; ++r)
    threads.emplace_back([&, r] {
      const std::string robot = "fill-r" + std::to_string(r);
      for (std::int64_t k; (k = next++) < rss_scans;)
        cl.ingest(requestFor(frames[static_cast<std::size_t>(k) % frames.size()], map, robot, "run", k, false));
    });
  for (auto& t : threads) t.join();
  const auto stats = cl.getStats(map);
  return {{"scans", stats.scans()},
          {"fill_s", msSince(t0) / 1000.0},
          {"server_rss_mb", static_cast<double>(bench::procStatusKb(server.pid(), "VmRSS")) / 1024.0},
          {"server_peak_rss_mb", static_cast<double>(bench::procStatusKb(server.pid(), "VmHWM")) / 1024.0},
          {"db_mb", static_cast<double>(stats.db_bytes()) / 1e6}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"SGLC service benchmark over loopback (JSON on stdout)."};
  app.set_version_flag("--version", std::string("sglc-bench ") + sglc::kVersion);
  Options options;
  addOptions(app, options);
  CLI11_PARSE(app, argc, argv);
  if (const std::string problem = sglc::tools::nonFiniteValue(app); !problem.empty()) {
    std::cerr << "sglc-bench: error: " << problem << std::endl;
    return 2;
  }

  ordered_json out;
  const Keyframes keyframes = renderKeyframes(options.frames, out);
  Server server = startServer(options);
  client::ConnectOptions co;
  co.default_deadline = std::chrono::milliseconds(60'000);
  const auto cl = client::Client::connect(server.address, co);
  if (!waitUntilServing(cl, server)) return 1;
  const std::string map = "bench-" + std::to_string(::getpid());
  cl.ensureMap(map);
  const bool started_here = static_cast<bool>(server.process);
  out["server"] = {{"address", server.address}, {"started_here", started_here}};
  const pid_t pid = started_here ? server.process->pid() : -1;
  out["map_ingest_only"] = benchMapIngest(cl, map, keyframes.map, pid);
  out["round_trip"] = benchRoundTrip(cl, map, keyframes.visitor, pid);
  ordered_json runs = ordered_json::array();
  for (const int n : options.robot_counts)
    if (n >= 1) runs.push_back(benchThroughputRun(cl, map, keyframes, n, options.seconds, pid));
  out["throughput"] = runs;
  if (options.rss_scans > 0 && server.process)
    out["memory"] = benchMemory(cl, map, keyframes.map, options.rss_scans, *server.process);
  std::cout << out.dump(2) << std::endl;
  server.process.reset();
  if (started_here) fs::remove_all(options.dir);
  return 0;
}
