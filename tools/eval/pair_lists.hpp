// The pair lists the pair and pose protocols evaluate: read from a file (SSC / LCR-Net style lists, or those
// sglc-sim writes), or derived from a source's ground-truth poses the way sglc-sim derives its files.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "sglc/types.hpp"
#include "source.hpp"

namespace sglc::eval {

// One row: frames i and j, a label (1 = loop, 0 = not), and optionally the relative pose of the pair.
struct PairRow {
  int i = 0, j = 0;
  int label = 1;
  std::optional<Mat4d> T;  // maps i's points into j's frame (LCR-Net loop lists)
};

// Rows of a pair file: "i j", "i j label" or "i j" + T (12 numbers, row-major 3x4). Lines starting with # are
// comments. Throws InputError naming the file and line of a malformed row, or for a file without pairs.
std::vector<PairRow> readPairs(const std::string& path);

// From the source's poses of its selected frames, as sglc-sim writes them (tools/sim/ground_truth.hpp):
// every loop (horizontal distance below positive_m, frames more than min_gap apart) plus negatives (farther
// than negative_m) sampled with `seed`, i the later frame; sglc-sim's pairs_distance.txt.
struct GroundTruthPairs {
  double positive_m = 3.0;
  double negative_m = 20.0;
  int min_gap = 50;
  std::uint64_t seed = 7;
};
std::vector<PairRow> distancePairs(const FrameSource& source, const GroundTruthPairs& options);

// Every pair closer than max_m in 3-D with frames more than min_gap apart, i the earlier frame, with its
// exact relative pose; sglc-sim's loop_distance4.txt.
std::vector<PairRow> posePairs(const FrameSource& source, double max_m, int min_gap);

}  // namespace sglc::eval
