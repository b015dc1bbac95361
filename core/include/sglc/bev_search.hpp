// Planar pose from the background alone: where landmarks give no coarse pose (a stretch of road without
// cars, trunks or poles), the labelled bird's-eye views of two scans of the same place still overlay at one
// heading and shift. An exhaustive search over heading and shift on a coarse grid, then a finer local search
// around the best few, gives starting poses close enough for the plane refinement.
#pragma once

#include <vector>

#include "sglc/background.hpp"
#include "sglc/config.hpp"
#include "sglc/types.hpp"

namespace sglc {

struct BevPose {
  Mat4d T = Mat4d::Identity();  // maps the candidate into the query frame (planar: z, roll, pitch zero)
  double score = 0.0;           // overlay score: matching structure cells (exact 2, neighbouring 1) / (2 * cells)
};

// The best `config.keep` distinct planar poses (best first) overlaying the candidate's structure cells
// (fence, building, vegetation; road says little about a shift) on the query's, with shifts up to
// config.max_shift_m on each axis and any heading. Deterministic. Empty when either view has no structure.
std::vector<BevPose> searchBevPose(const std::vector<BevCell>& query, const std::vector<BevCell>& candidate,
                                   double stored_cell, const BevSearchConfig& config);

}  // namespace sglc
