// sim_info.json, the record of a written sequence: everything needed to reproduce it (seed, trajectory,
// sensor, world, noise and ground-truth settings) and a summary of what was written.
#pragma once

#include <string>
#include <vector>

#include "sim/sequence.hpp"

namespace sglc::sim {

// The top 3 rows of T, row-major (KITTI pose-file order).
std::vector<double> poseRow12(const Mat4d& T);

// Writes sim_info.json at `path` for the sequence `summary` describes. Throws InputError when it cannot.
void writeSimInfo(const std::string& path, const Simulator& sim, const SequenceOptions& opt,
                  const SequenceSummary& summary);

}  // namespace sglc::sim
