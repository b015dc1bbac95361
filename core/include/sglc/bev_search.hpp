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
// config.max_shift_m on each axis and any heading, or, when `headings` (radians) is not empty, only the coarse
// heading steps within one step of one of them; at each heading step the best shifts_per_heading shifts, each
// more than two cells from the ones before (along a corridor, shifts score alike). Without `fine`, the coarse
// overlays are returned as they are
// (within a cell and a heading step; the plane refinement converges from there) instead of being searched
// again around on the stored cells, which costs most of the time. Deterministic. Empty when either view has no
// structure.
std::vector<BevPose> searchBevPose(const std::vector<BevCell>& query, const std::vector<BevCell>& candidate,
                                   double stored_cell, const BevSearchConfig& config,
                                   const std::vector<double>& headings = {}, bool fine = true,
                                   int shifts_per_heading = 1);

// Headings (radians, in [0, 2 pi)) that turn the candidate's walls parallel to the query's: the vertical planes'
// horizontal normal directions, folded to [0, 180) deg, are histogrammed per degree in each scan, and the best
// `peaks` circular correlation maxima give each heading twice (h and h + 180 deg: a normal's side depends on where
// the sensor stood). A shift does not change a wall's direction, so they hold however far apart the scans are;
// streets of parallel and square walls give peaks 90 deg apart, hence more than one. Empty when either scan has
// no vertical plane. Deterministic.
std::vector<double> wallHeadings(const std::vector<Plane>& query, const std::vector<Plane>& candidate, int peaks);

}  // namespace sglc
