// sglc-bench-storage: speed and size of the map database, printed as one JSON object.
//
// Fingerprints come from simulated HDL-64 frames (KITTI 00's path when ../shared/data is present, else the
// built-in route). Larger maps reuse them with perturbed scan descriptors (each a distinct unit vector near a
// real one), so the index sees realistic descriptor statistics.
//
//   build/bin/sglc-bench-storage [--dir /tmp/sglc-bench] [--frames 300] [--scans 100000] [--million]
#include <malloc.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>

#include "bench/kitti_path.hpp"
#include "sglc/elapsed.hpp"
#include "sglc/io.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/storage/map_store.hpp"
#include "sglc/version.hpp"
#include "sim/simulator.hpp"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using namespace sglc;

// The process's resident memory (MB), from /proc.
double residentMb() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);)
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  return 0;
}

nlohmann::ordered_json summary(const std::vector<double>& v) {
  return {{"median_ms", percentile(v, 0.5)}, {"p90_ms", percentile(v, 0.9)}, {"n", v.size()}};
}

std::vector<float> perturb(const std::vector<float>& d, std::mt19937_64& rng, float sigma) {
  std::normal_distribution<float> g(0.0f, sigma);
  std::vector<float> out(d.size());
  double norm = 0;
  for (std::size_t i = 0; i < d.size(); ++i) {
    out[i] = std::max(0.0f, d[i] + g(rng));
    norm += double(out[i]) * out[i];
  }
  for (auto& v : out) v = static_cast<float>(v / std::sqrt(norm));
  return out;
}

// Adds `count` scans cycling through the base fingerprints with perturbed descriptors.
void fill(storage::MapStore& store, const std::string& map, const std::vector<Fingerprint>& base, std::int64_t first,
          std::int64_t count, std::mt19937_64& rng, std::vector<std::vector<float>>* keep_some) {
  for (std::int64_t i = first; i < first + count; ++i) {
    Fingerprint fp = base[static_cast<std::size_t>(i) % base.size()];
    fp.descriptor = perturb(fp.descriptor, rng, 0.01f);
    storage::NewScan ns;
    ns.map = map;
    ns.robot = "r" + std::to_string(i % 4);
    ns.session = "s" + std::to_string(i / 25000);
    ns.seq = i;
    ns.fingerprint = &fp;
    store.addScan(ns);
    if (keep_some && i % 997 == 0) keep_some->push_back(fp.descriptor);
  }
}

struct Options {
  std::string dir = (fs::temp_directory_path() / "sglc-bench-storage").string();
  int frames = 300;
  std::int64_t scans = 100000;
  bool million = false;
  std::string data = "../shared/data";
  std::vector<int> nprobes{storage::IndexOptions{}.ivf_nprobe};
  std::string postgres;  // a PostgreSQL database URL: the store and write-rate figures on it too
  double write_seconds = 10;
};

void addOptions(CLI::App& app, Options& o) {
  app.add_option("--dir", o.dir, "scratch directory (removed first)")->capture_default_str();
  app.add_option("--frames", o.frames, "simulated frames to fingerprint")->capture_default_str();
  app.add_option("--scans", o.scans, "size of the exact-search map")->capture_default_str();
  app.add_flag("--million", o.million, "also build a 1M-scan map with the approximate (IVF) index");
  app.add_option("--postgres", o.postgres,
                 "PostgreSQL database URL: also measure storing, fetching and the write rate at saturation there "
                 "(one store per writer, as replicas; a map of its own, deleted afterwards)");
  app.add_option("--write-seconds", o.write_seconds, "length of each write-rate run (s)")->capture_default_str();
  app.add_option("--data", o.data, "shared data directory (KITTI poses)")->capture_default_str();
  app.add_option("--ivf-nprobe", o.nprobes, "IVF cells visited per search (a list is measured value by value)")
      ->capture_default_str()
      ->delimiter(',');
}

// KITTI 00's path when the shared data has it, else the built-in route.
// 1. Realistic fingerprints: of up to `frames` simulated frames spread over the trajectory.
std::vector<Fingerprint> simulatedFingerprints(const Pipeline& pipeline, const sim::Trajectory& traj, int frames,
                                               nlohmann::ordered_json& out) {
  sim::SimConfig sc;
  sc.threads = 2;
  const sim::Simulator simulator(traj, sc);
  std::vector<Fingerprint> base;
  std::vector<double> blob_bytes;
  const int stride = std::max(1, simulator.numFrames() / frames);
  for (int f = 0; f < simulator.numFrames() && static_cast<int>(base.size()) < frames; f += stride) {
    base.push_back(pipeline.fingerprint(simulator.render(f).scan));
    blob_bytes.push_back(static_cast<double>(serialize(base.back()).size()));
  }
  out["source"] = traj.source;
  out["fingerprints"] = base.size();
  out["fingerprint_bytes"] = {{"median", percentile(blob_bytes, 0.5)}, {"max", percentile(blob_bytes, 1.0)}};
  return base;
}

// 2. Store with synchronous=FULL, then fetches from the database and from the cache.
void benchStoreAndFetch(const storage::StoreOptions& o, const std::vector<Fingerprint>& base,
                        nlohmann::ordered_json& out) {
  auto store = storage::MapStore::open(o);
  store->createMap("m", base.front().layout.scanDim());
  std::vector<double> store_ms, fetch_ms, cold_ms;
  std::vector<std::int64_t> ids;
  for (std::size_t i = 0; i < base.size(); ++i) {
    storage::NewScan ns{
        .map = "m", .robot = "r", .session = "s", .seq = static_cast<std::int64_t>(i), .fingerprint = &base[i]};
    const auto t0 = Clock::now();
    ids.push_back(store->addScan(ns));
    store_ms.push_back(msSince(t0));
  }
  for (auto id : ids) {
    const auto t0 = Clock::now();
    store->fingerprint(id);
    cold_ms.push_back(msSince(t0));
  }
  for (int rep = 0; rep < 5; ++rep)
    for (auto id : ids) {
      const auto t0 = Clock::now();
      store->fingerprint(id);
      fetch_ms.push_back(msSince(t0));
    }
  out["store_full_sync"] = summary(store_ms);
  out["fetch_from_db"] = summary(cold_ms);
  out["fetch_from_cache"] = summary(fetch_ms);
  const auto st = store->stats();
  out["bytes_per_scan_db"] = static_cast<double>(st.db_bytes) / static_cast<double>(st.scans);
  store->deleteMap("m");
}

// Scans stored per second with `writers` threads writing at once for `seconds`, each through a store of its own
// (as replicas do) when `store_per_writer`, else through one store; with every write's latency.
nlohmann::ordered_json writeRate(const storage::StoreOptions& o, const std::vector<Fingerprint>& base, int writers,
                                 bool store_per_writer, double seconds) {
  std::vector<std::unique_ptr<storage::MapStore>> stores;
  for (int w = 0; w < (store_per_writer ? writers : 1); ++w) stores.push_back(storage::MapStore::open(o));
  const std::string map = "rate-" + std::to_string(writers);
  stores[0]->createMap(map, base.front().layout.scanDim());
  std::vector<std::vector<double>> ms(static_cast<std::size_t>(writers));
  const auto t0 = Clock::now();
  std::vector<std::thread> threads;
  for (int w = 0; w < writers; ++w)
    threads.emplace_back([&, w] {
      auto& store = *stores[store_per_writer ? static_cast<std::size_t>(w) : 0];
      for (std::int64_t i = 0; msSince(t0) < seconds * 1000; ++i) {
        const auto& fp = base[static_cast<std::size_t>(i) % base.size()];
        const auto t = Clock::now();
        store.addScan({.map = map, .robot = "w" + std::to_string(w), .session = "s", .seq = i, .fingerprint = &fp});
        ms[static_cast<std::size_t>(w)].push_back(msSince(t));
      }
    });
  for (auto& t : threads) t.join();
  const double elapsed = msSince(t0) / 1000.0;
  std::vector<double> all;
  for (const auto& v : ms) all.insert(all.end(), v.begin(), v.end());
  stores[0]->deleteMap(map);
  nlohmann::ordered_json out = summary(all);
  out["writers"] = writers;
  out["scans_per_s"] = static_cast<double>(all.size()) / elapsed;
  return out;
}

// The same figures on PostgreSQL (full durability: synchronous_commit on), and the write rate of 1, 2 and 4
// writers on both back-ends.
void benchWriteRates(const Options& options, const std::vector<Fingerprint>& base, nlohmann::ordered_json& out) {
  storage::StoreOptions sqlite;
  sqlite.path = options.dir + "/rate.db";
  sqlite.sync = storage::StoreOptions::Sync::kFull;
  nlohmann::ordered_json rates = nlohmann::ordered_json::array();
  for (const int w : {1, 2, 4}) rates.push_back(writeRate(sqlite, base, w, false, options.write_seconds));
  out["sqlite_write_rate"] = rates;
  if (options.postgres.empty()) return;
  storage::StoreOptions pg = sqlite;
  pg.path = options.postgres;
  nlohmann::ordered_json pg_out;
  benchStoreAndFetch(pg, base, pg_out);
  rates = nlohmann::ordered_json::array();
  for (const int w : {1, 2, 4}) rates.push_back(writeRate(pg, base, w, true, options.write_seconds));
  pg_out["write_rate_store_per_writer"] = rates;
  out["postgres"] = pg_out;
}

// Top-50 exact searches near the kept descriptors, plain and with every filter.
void benchExactSearch(const storage::MapStore& store, const std::vector<std::vector<float>>& queries,
                      std::int64_t scans, std::mt19937_64& rng, nlohmann::ordered_json& out) {
  std::vector<double> search_ms, filtered_ms;
  for (const auto& q : queries) {
    storage::SearchRequest req{.map = "m", .descriptor = perturb(q, rng, 0.005f), .k = 50};
    auto t1 = Clock::now();
    store.search(req);
    search_ms.push_back(msSince(t1));
    req.exclude_robots = {"r1"};
    req.self_robot = "r0";
    req.self_session = "s0";
    req.exclude_recent = 100;
    t1 = Clock::now();
    store.search(req);
    filtered_ms.push_back(msSince(t1));
  }
  out["search_top50_exact"] = summary(search_ms);
  out["search_top50_exact"]["scans"] = scans;
  out["search_top50_exact_filtered"] = summary(filtered_ms);
}

// 3. A large map, exact search, reopen (with the index snapshot, then rebuilding the index).
void benchLargeMap(const std::string& dir, const std::vector<Fingerprint>& base, std::int64_t scans,
                   std::mt19937_64& rng, nlohmann::ordered_json& out) {
  storage::StoreOptions o;
  o.path = dir + "/big.db";
  o.sync = storage::StoreOptions::Sync::kOff;  // bulk fill; the timed store above is FULL
  std::vector<std::vector<float>> queries;
  auto t0 = Clock::now();
  {
    auto store = storage::MapStore::open(o);
    store->createMap("m", base.front().layout.scanDim());
    fill(*store, "m", base, 0, scans, rng, &queries);
    out["fill_s"] = msSince(t0) / 1000.0;
    benchExactSearch(*store, queries, scans, rng, out);
    const auto st = store->stats();
    out["big_map"] = {{"scans", st.scans},
                      {"db_bytes", st.db_bytes},
                      {"bytes_per_scan", static_cast<double>(st.db_bytes) / static_cast<double>(st.scans)}};
  }
  t0 = Clock::now();
  { auto store = storage::MapStore::open(o); }
  out["open_with_snapshot_s"] = msSince(t0) / 1000.0;
  fs::remove_all(o.path + ".index");
  o.cache_mb = 0;    // the index alone
  ::malloc_trim(0);  // the stores above gave their memory back: measure from what is really held
  const double rss_before = residentMb();
  t0 = Clock::now();
  {
    auto store = storage::MapStore::open(o);
    out["open_rebuild_s"] = msSince(t0) / 1000.0;
    // What a replica holds in memory per scan: the FAISS index, the entries the filters read, the catalogue.
    out["index_rss_mb_per_million_scans"] = (residentMb() - rss_before) * 1e6 / static_cast<double>(scans);
  }
}

// Fingerprints of `base` reduced to what the index needs: nodes and descriptor only.
std::vector<Fingerprint> descriptorOnly(const std::vector<Fingerprint>& base) {
  std::vector<Fingerprint> small;
  for (const auto& fp : base) {
    Fingerprint s;
    s.layout = fp.layout;
    s.d_max = fp.d_max;
    s.d_i = fp.d_i;
    s.background_cell = fp.background_cell;
    s.plane_voxel = fp.plane_voxel;
    s.descriptor = fp.descriptor;
    s.instance_offsets = {0};
    small.push_back(std::move(s));
  }
  return small;
}

// One IVF search run with `nprobe` cells: latency, open time and recall@50 against the exact hits.
nlohmann::ordered_json ivfRun(storage::StoreOptions o, int nprobe, const std::vector<storage::SearchRequest>& requests,
                              const std::vector<std::vector<storage::SearchHit>>& truth) {
  o.index.type = storage::IndexOptions::Type::kIvf;
  o.index.ivf_nprobe = nprobe;
  const auto t0 = Clock::now();
  auto approx = storage::MapStore::open(o);
  const double open_s = msSince(t0) / 1000.0;
  std::vector<double> approx_ms;
  std::size_t hit = 0, total = 0;
  for (std::size_t qi = 0; qi < requests.size(); ++qi) {
    const auto t1 = Clock::now();
    const auto a = approx->search(requests[qi]);
    approx_ms.push_back(msSince(t1));
    for (const auto& h : truth[qi])
      hit += std::any_of(a.begin(), a.end(), [&](const storage::SearchHit& x) { return x.scan_id == h.scan_id; });
    total += truth[qi].size();
  }
  auto run = summary(approx_ms);
  run["nprobe"] = nprobe;
  run["open_s"] = open_s;
  run["recall_at_50"] = static_cast<double>(hit) / static_cast<double>(std::max<std::size_t>(total, 1));
  return run;
}

// 4. One million scans with the approximate index, recall against exact search.
void benchMillion(const std::string& dir, const std::vector<Fingerprint>& base, const std::vector<int>& nprobes,
                  std::mt19937_64& rng, nlohmann::ordered_json& out) {
  storage::StoreOptions o;
  o.path = dir + "/million.db";
  o.sync = storage::StoreOptions::Sync::kOff;
  std::vector<std::vector<float>> queries;
  const auto t0 = Clock::now();
  {
    auto store = storage::MapStore::open(o);
    store->createMap("m", base.front().layout.scanDim());
    fill(*store, "m", descriptorOnly(base), 0, 1000000, rng, &queries);
  }
  out["million_fill_s"] = msSince(t0) / 1000.0;
  queries.resize(std::min<std::size_t>(queries.size(), 200));
  auto exact = storage::MapStore::open(o);
  std::vector<std::vector<storage::SearchHit>> truth;
  std::vector<storage::SearchRequest> requests;
  std::vector<double> exact_ms;
  for (const auto& q0 : queries) {
    requests.push_back({.map = "m", .descriptor = perturb(q0, rng, 0.005f), .k = 50});
    const auto t1 = Clock::now();
    truth.push_back(exact->search(requests.back()));
    exact_ms.push_back(msSince(t1));
  }
  exact.reset();
  out["million_search_top50_exact"] = summary(exact_ms);
  nlohmann::ordered_json ivf_runs = nlohmann::ordered_json::array();
  for (const int nprobe : nprobes) ivf_runs.push_back(ivfRun(o, nprobe, requests, truth));
  out["million_search_top50_ivf"] = ivf_runs;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Map database benchmark (JSON on stdout)."};
  app.set_version_flag("--version", std::string("sglc-bench-storage ") + sglc::kVersion);
  Options options;
  addOptions(app, options);
  CLI11_PARSE(app, argc, argv);

  try {
    fs::remove_all(options.dir);
    fs::create_directories(options.dir);
    nlohmann::ordered_json out;
    const Pipeline pipeline;
    const auto base = simulatedFingerprints(pipeline, bench::kitti00OrLoopRoute(options.data), options.frames, out);
    std::mt19937_64 rng(42);
    storage::StoreOptions full;
    full.path = options.dir + "/full.db";
    full.sync = storage::StoreOptions::Sync::kFull;
    benchStoreAndFetch(full, base, out);
    benchWriteRates(options, base, out);
    benchLargeMap(options.dir, base, options.scans, rng, out);
    if (options.million) benchMillion(options.dir, base, options.nprobes, rng, out);
    std::cout << out.dump(2) << std::endl;
  } catch (const std::exception& e) {  // an unreachable database, a full disk: one clear line
    std::cerr << "sglc-bench-storage: error: " << e.what() << std::endl;
    fs::remove_all(options.dir);
    return 1;
  }
  fs::remove_all(options.dir);
  return 0;
}
