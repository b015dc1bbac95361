// A scan's sweep on the wire (sglc.v1.Scan.point_times and .twist): per-point times as float32 little-endian,
// one per point or none, and the twist as 3 + 3 doubles or nothing. Every failure throws WireError with a message
// that says what is wrong.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "sglc/deskew.hpp"
#include "sglc/v1/sglc.pb.h"
#include "sglc/wire/error.hpp"

namespace sglc::wire {

inline constexpr std::size_t kTimeBytes = 4;  // float32 per point

std::string packPointTimes(const std::vector<float>& times);
// Throws when the byte length is not a multiple of 4; does not look at the values.
std::vector<float> unpackPointTimes(std::string_view bytes);
void packTwist(const Twist& twist, v1::Twist* out);
// Fills scan.point_times and scan.twist (when the sweep has one). Throws when the times are neither absent nor
// one per point of the scan's packed points.
void packSweep(const ScanSweep& sweep, v1::Scan* out);

// What a server accepts for a scan of `point_count` points: times absent or exactly one per point, each finite
// and within 1 s of the stamp (the message names the first bad one); a twist that is absent (no values) or
// carries 3 + 3 finite values within sglc::kMaxSweepSpeed and kMaxSweepTurnRate. A twist without times is
// refused: it would do nothing.
ScanSweep decodeSweep(std::string_view point_times, const v1::Twist& twist, std::size_t point_count);

}  // namespace sglc::wire
