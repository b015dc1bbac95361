// Per-stage speed of the engine on real KITTI scans (single thread). Run with
//   build/bin/sglc-bench-core --benchmark_repetitions=10 --benchmark_report_aggregates_only=true
// and read the medians. Data: ../shared/data/semantickitti_scans (or $SGLC_DATA/semantickitti_scans).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <numbers>

#include "benchmark_main.hpp"
#include "sglc/io.hpp"
#include "sglc/labeller.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/view_context.hpp"

namespace {

std::string dataDir() {
  const char* env = std::getenv("SGLC_DATA");
  return std::string(env ? env : "../shared/data") + "/semantickitti_scans/sequences/00";
}

struct Fixture {
  sglc::Pipeline pipeline;
  std::map<std::string, sglc::LabelledScan> scans;
  std::map<std::string, sglc::Fingerprint> fps;
  bool ok = false;
  Fixture() {
    const auto dir = dataDir();
    if (!std::filesystem::exists(dir)) return;
    for (const char* f : {"000052", "004501", "000088", "000850"}) {
      scans[f] = sglc::readScan(dir + "/velodyne/" + f + ".bin", dir + "/labels/" + f + ".label");
      fps[f] = pipeline.fingerprint(scans[f]);
    }
    // 4501 with its landmarks unlabelled: the loop only the background can register.
    auto bare = scans.at("004501");
    const sglc::LabelMap labels(pipeline.config().labels);
    for (auto& l : bare.labels)
      if (labels.nodeClass(l) >= 0) l = 0;
    fps["004501-bare"] = pipeline.fingerprint(bare);
    ok = true;
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

bool ready(benchmark::State& state) {
  if (fixture().ok) return true;
  state.SkipWithError(("real scans not found under " + dataDir()).c_str());
  return false;
}

void BM_Fingerprint(benchmark::State& state) {
  if (!ready(state)) return;
  const auto& scan = fixture().scans.at("000052");
  for (auto _ : state) benchmark::DoNotOptimize(fixture().pipeline.fingerprint(scan));
  state.counters["points"] = static_cast<double>(scan.points.size());
}

// The built-in labeller alone on a real HDL-64 scan (x, y, z only), with the engine's default parameters.
void BM_Labeller(benchmark::State& state) {
  if (!ready(state)) return;
  const auto& scan = fixture().scans.at("000052");
  const auto& config = fixture().pipeline.config().labeller;
  for (auto _ : state) benchmark::DoNotOptimize(sglc::labelScene(scan.points, config));
  state.counters["points"] = static_cast<double>(scan.points.size());
}

// Fingerprint of the same scan sent without labels: the labeller, then the usual pipeline.
void BM_FingerprintWithoutLabels(benchmark::State& state) {
  if (!ready(state)) return;
  sglc::LabelledScan bare;
  bare.points = fixture().scans.at("000052").points;
  for (auto _ : state) benchmark::DoNotOptimize(fixture().pipeline.fingerprint(bare));
}

void BM_VerifyLoop(benchmark::State& state) {
  if (!ready(state)) return;
  auto& f = fixture();
  for (auto _ : state) benchmark::DoNotOptimize(f.pipeline.verify(f.fps.at("000052"), f.fps.at("004501")));
}

// A hard negative: same street 30 m away, so many nodes match and RANSAC runs in full.
void BM_VerifyNegative(benchmark::State& state) {
  if (!ready(state)) return;
  auto& f = fixture();
  for (auto _ : state) benchmark::DoNotOptimize(f.pipeline.verify(f.fps.at("000052"), f.fps.at("000088")));
}

void BM_Refine(benchmark::State& state) {
  if (!ready(state)) return;
  auto& f = fixture();
  const auto verified = f.pipeline.verify(f.fps.at("000052"), f.fps.at("004501"));
  for (auto _ : state) {
    auto r = verified;
    f.pipeline.refine(f.fps.at("000052"), f.fps.at("004501"), r);
    benchmark::DoNotOptimize(r);
  }
}

// A known loop without landmarks (Pipeline::refine with known_loop): background search, then the plane stage
// from the best overlays.
void BM_RefineKnownLoopFromBackground(benchmark::State& state) {
  if (!ready(state)) return;
  auto& f = fixture();
  // Without background-only loops (verify's `background` false): with them the pair is verified from its
  // background, already posed, and refine would return at once.
  const auto rejected = f.pipeline.verify(f.fps.at("000052"), f.fps.at("004501-bare"), /*background=*/false);
  if (rejected.is_loop || rejected.refined) {
    state.SkipWithError("the bare pair was verified: no known-loop search to time");
    return;
  }
  for (auto _ : state) {
    auto r = rejected;
    f.pipeline.refine(f.fps.at("000052"), f.fps.at("004501-bare"), r, true);
    benchmark::DoNotOptimize(r);
  }
}

void BM_Serialize(benchmark::State& state) {
  if (!ready(state)) return;
  const auto& fp = fixture().fps.at("000052");
  std::size_t bytes = 0;
  for (auto _ : state) {
    const auto blob = sglc::serialize(fp);
    bytes = blob.size();
    benchmark::DoNotOptimize(blob);
  }
  state.counters["bytes"] = static_cast<double>(bytes);
}

void BM_Deserialize(benchmark::State& state) {
  if (!ready(state)) return;
  const auto blob = sglc::serialize(fixture().fps.at("000052"));
  for (auto _ : state) benchmark::DoNotOptimize(sglc::deserialize(blob));
}

// The view context of a real HDL-64 scan's stored background: what a narrow query's ranking builds for every
// stored scan it compares (LoopFinder::viewRanked).
void BM_ViewContext(benchmark::State& state) {
  if (!ready(state)) return;
  const auto& fp = fixture().fps.at("004501");
  const auto& config = fixture().pipeline.config().view_search;
  for (auto _ : state) benchmark::DoNotOptimize(sglc::viewContext(fp.background, fp.background_cell, config));
  state.counters["cells"] = static_cast<double>(fp.background.size());
}

// One comparison of a narrow query (a 70 deg wedge of 000052) with a stored scan's context, at all 128 headings.
void BM_ViewMatch(benchmark::State& state) {
  if (!ready(state)) return;
  auto& f = fixture();
  const auto& config = f.pipeline.config().view_search;
  std::vector<sglc::BevCell> wedge;
  for (const auto& c : f.fps.at("000052").background)
    if (std::abs(std::atan2(c.iy + 0.5, c.ix + 0.5)) <= 35.0 * std::numbers::pi / 180.0) wedge.push_back(c);
  const sglc::ViewMatcher matcher(sglc::viewContext(wedge, f.fps.at("000052").background_cell, config));
  const auto other = sglc::viewContext(f.fps.at("004501").background, f.fps.at("004501").background_cell, config);
  for (auto _ : state) benchmark::DoNotOptimize(matcher.match(other));
}

// A narrow query (a 70 deg wedge of 000052) ranking 1,000 stored scans by their view contexts (what
// LoopFinder::viewRanked does with a map's scans): cold, every stored context computed afresh as every query did
// before the contexts were kept with the fingerprints (Arg 0); warm, as every query after the first does now
// (Arg 1). Per stored scan: items_per_second.
void BM_ViewRankStoredScans(benchmark::State& state) {
  if (!ready(state)) return;
  auto& f = fixture();
  sglc::Fingerprint query = f.fps.at("000052");
  std::erase_if(query.background, [](const sglc::BevCell& c) {
    return std::abs(std::atan2(c.iy + 0.5, c.ix + 0.5)) > 35.0 * std::numbers::pi / 180.0;
  });
  query.finalize();
  const auto ranking = f.pipeline.viewRanking(query);
  std::vector<const sglc::Fingerprint*> stored;
  for (int i = 0; i < 250; ++i)
    for (const char* name : {"000052", "004501", "000088", "000850"}) stored.push_back(&f.fps.at(name));
  const bool warm = state.range(0) == 1;
  for (const auto* fp : stored) fp->view_memo.clear();
  if (warm)
    for (const auto* fp : stored) benchmark::DoNotOptimize(ranking.similarity(*fp));
  for (auto _ : state) {
    double sum = 0;
    for (const auto* fp : stored) {
      if (!warm) fp->view_memo.clear();  // the 4 scans repeat: each comparison computes its context afresh
      sum += ranking.similarity(*fp);
    }
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * stored.size()));
}

}  // namespace

BENCHMARK(BM_Fingerprint)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Labeller)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FingerprintWithoutLabels)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_VerifyLoop)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_VerifyNegative)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Refine)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RefineKnownLoopFromBackground)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Serialize)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Deserialize)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ViewContext)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ViewMatch)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ViewRankStoredScans)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

int main(int argc, char** argv) { return sglc::bench::runBenchmarks("sglc-bench-core", argc, argv); }
