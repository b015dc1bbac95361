// sglc-bench-bags: how fast a drive is read, scan by scan, from a sequence directory and from bags of the same
// drive (MCAP with zstd or lz4 chunks, rosbag2 .db3). Each source is read whole (every scan decoded to points,
// as `sglc ingest` reads it), `--repeat` times in turn, and the CPU time of this process per pass is measured;
// prints one JSON object with the median scans per CPU-second of each source and its ratio to the directory.
// scripts/bench-bags.sh prepares the files (the simulator, then tests/interop/write_bag.mjs).
#include <time.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <iostream>
#include <nlohmann/json.hpp>

#include "sglc/bag_drive.hpp"
#include "sglc/io.hpp"
#include "sglc/sequence.hpp"

namespace {

double cpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// One pass: every scan decoded; returns (scans, points) so the work cannot be skipped.
std::pair<std::size_t, std::size_t> readDirectory(const std::string& dir) {
  const auto seq = sglc::openSequence(dir);
  std::size_t points = 0;
  for (const auto& f : seq.frames) points += sglc::readScan(f.scan_path, "").points.size();
  return {seq.frames.size(), points};
}

std::pair<std::size_t, std::size_t> readBag(const std::string& path) {
  sglc::BagDriveOptions o;
  o.points_topic = "/points";
  o.odom_topic = "/odom";
  o.keyframe_m = o.keyframe_deg = 0;
  sglc::BagDrive drive(path, o);
  std::size_t points = 0;
  for (std::size_t i = 0; i < drive.frames().size(); ++i) points += drive.cloud(i).points.size();
  return {drive.frames().size(), points};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Scans per CPU-second read from a sequence directory and from bags of the same drive"};
  std::string dir, zstd, lz4, db3;
  int repeat = 5;
  app.add_option("--dir", dir, "sequence directory")->required();
  app.add_option("--mcap-zstd", zstd, "the drive as MCAP, zstd chunks");
  app.add_option("--mcap-lz4", lz4, "the drive as MCAP, lz4 chunks");
  app.add_option("--db3", db3, "the drive as a rosbag2 .db3 directory");
  app.add_option("--repeat", repeat, "passes over each source, in turn")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    struct Source {
      std::string name, path;
      bool bag;
      std::vector<double> rates;
      std::size_t scans = 0, points = 0;
    };
    std::vector<Source> sources{{"directory", dir, false, {}}};
    if (!zstd.empty()) sources.push_back({"mcap_zstd", zstd, true, {}});
    if (!lz4.empty()) sources.push_back({"mcap_lz4", lz4, true, {}});
    if (!db3.empty()) sources.push_back({"db3", db3, true, {}});
    for (int r = 0; r < repeat; ++r)
      for (auto& s : sources) {
        const double t0 = cpuSeconds();
        const auto [scans, points] = s.bag ? readBag(s.path) : readDirectory(s.path);
        const double t = cpuSeconds() - t0;
        s.scans = scans;
        s.points = points;
        s.rates.push_back(static_cast<double>(scans) / std::max(t, 1e-9));
      }
    nlohmann::json out;
    const double base = median(sources[0].rates);
    for (const auto& s : sources) {
      if (s.points != sources[0].points)
        throw std::runtime_error(s.name + " gave " + std::to_string(s.points) + " points, the directory " +
                                 std::to_string(sources[0].points));
      out[s.name] = {{"scans", s.scans},
                     {"scans_per_cpu_second_median", median(s.rates)},
                     {"ratio_to_directory", median(s.rates) / base}};
    }
    out["repeat"] = repeat;
    std::cout << out.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::cerr << "sglc-bench-bags: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
