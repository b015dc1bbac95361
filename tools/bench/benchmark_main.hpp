// main() of the Google Benchmark tools: --version is answered before Google Benchmark sees the command line
// (it would reject the flag), then the benchmarks run as BENCHMARK_MAIN() runs them.
#pragma once

#include <benchmark/benchmark.h>

#include <algorithm>
#include <iostream>
#include <string_view>

#include "sglc/version.hpp"

namespace sglc::bench {

inline int runBenchmarks(const char* name, int argc, char** argv) {
  if (std::any_of(argv + 1, argv + argc, [](const char* a) { return std::string_view(a) == "--version"; })) {
    std::cout << name << " " << sglc::kVersion << std::endl;
    return 0;
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

}  // namespace sglc::bench
