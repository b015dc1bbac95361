// Speed of the simulator (frames/s = items_per_second). Run with
//   build/bin/sglc-bench-sim --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
// and read the medians. KITTI 00 cases need ../shared/data (or $SGLC_DATA) and are skipped without it.
//
//   BM_WorldBuild/...          building the world around a trajectory (once per run of sglc-sim)
//   BM_Render/B/T              one frame with B beams, T threads inside the frame (column split)
//   BM_RenderFrames/B/T        T frames at once, one thread each (what sglc-sim does), frames/s overall
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include "bench/benchmark_main.hpp"
#include "sim/simulator.hpp"

namespace {

using sglc::sim::SensorConfig;
using sglc::sim::SimConfig;
using sglc::sim::Simulator;
using sglc::sim::Trajectory;

std::string dataDir() {
  const char* env = std::getenv("SGLC_DATA");
  return env ? env : "../shared/data";
}

const Trajectory* kitti00() {
  static std::unique_ptr<Trajectory> t = [] {
    const std::string poses = dataDir() + "/kitti_odometry_gt_poses/poses/00.txt";
    const std::string calib = dataDir() + "/semantickitti_scans/sequences/00/calib.txt";
    if (!std::filesystem::exists(poses) || !std::filesystem::exists(calib)) return std::unique_ptr<Trajectory>();
    return std::make_unique<Trajectory>(sglc::sim::loadKittiTrajectory(poses, calib));
  }();
  return t.get();
}

const Trajectory& loop() {
  static const Trajectory t = sglc::sim::loopRoute();
  return t;
}

// One simulator per (route, beams), built on first use.
const Simulator* simulator(bool kitti, int beams) {
  static std::mutex mutex;
  static std::map<std::pair<bool, int>, std::unique_ptr<Simulator>> cache;
  std::lock_guard lock(mutex);
  auto& slot = cache[{kitti, beams}];
  if (!slot) {
    const Trajectory* t = kitti ? kitti00() : &loop();
    if (!t) return nullptr;
    SimConfig cfg;
    cfg.sensor = SensorConfig::preset(beams);
    slot = std::make_unique<Simulator>(*t, cfg);
  }
  return slot.get();
}

void BM_WorldBuild(benchmark::State& state) {
  const bool kitti = state.range(0) == 1;
  const Trajectory* t = kitti ? kitti00() : &loop();
  if (!t) {
    state.SkipWithError("KITTI 00 poses not found under $SGLC_DATA or ../shared/data");
    return;
  }
  for (auto _ : state) benchmark::DoNotOptimize(sglc::sim::World(t->poses, 7));
  state.SetLabel(kitti ? "kitti00" : "loop");
}

void BM_Render(benchmark::State& state, bool kitti) {
  const Simulator* sim = simulator(kitti, static_cast<int>(state.range(0)));
  if (!sim) {
    state.SkipWithError("KITTI 00 poses not found under $SGLC_DATA or ../shared/data");
    return;
  }
  const int threads = static_cast<int>(state.range(1));
  sglc::sim::Frame frame;
  int k = 0;
  std::size_t points = 0;
  for (auto _ : state) {
    sim->render((k * 37) % sim->numFrames(), frame, threads);
    points += frame.scan.points.size();
    ++k;
  }
  state.SetItemsProcessed(k);
  state.counters["points"] = static_cast<double>(points) / std::max(1, k);
}

void BM_RenderFrames(benchmark::State& state, bool kitti) {
  const Simulator* sim = simulator(kitti, static_cast<int>(state.range(0)));
  if (!sim) {
    state.SkipWithError("KITTI 00 poses not found under $SGLC_DATA or ../shared/data");
    return;
  }
  const int threads = static_cast<int>(state.range(1));
  std::vector<sglc::sim::Frame> frames(threads);
  int k = 0;
  for (auto _ : state) {
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t)
      pool.emplace_back([&, t] { sim->render(((k + t) * 37) % sim->numFrames(), frames[t], 1); });
    for (auto& th : pool) th.join();
    k += threads;
  }
  state.SetItemsProcessed(k);
}

}  // namespace

BENCHMARK(BM_WorldBuild)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Render, loop, false)
    ->Args({64, 1})
    ->Args({64, 2})
    ->Args({32, 1})
    ->Args({128, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Render, kitti00, true)->Args({64, 1})->Args({64, 2})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_RenderFrames, loop, false)->Args({64, 2})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_RenderFrames, kitti00, true)->Args({64, 2})->Unit(benchmark::kMillisecond)->UseRealTime();

int main(int argc, char** argv) { return sglc::bench::runBenchmarks("sglc-bench-sim", argc, argv); }
