// Stage timings as the service and the tools report them: milliseconds on the steady clock.
#pragma once

#include <chrono>

namespace sglc {

using Clock = std::chrono::steady_clock;

inline double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace sglc
