// Ground truth derived from the exact poses of the rendered frames: SSC-style distance pair lists,
// loop_distance4-style rows with relative poses, and a drifting odometry trajectory for SLAM tests.
//
// All functions take the selected frames as `poses[k]` (LiDAR -> world) and `source[k]` (the trajectory
// frame index of output frame k, ascending). Pair indices are output indices k.
#pragma once

#include <cstdint>
#include <vector>

#include "sglc/types.hpp"

namespace sglc::sim {

struct PairListConfig {
  double positive_m = 3.0;          // loop if the horizontal (x, y) distance is below this
  double negative_m = 20.0;         // non-loop if the horizontal distance is above this
  int min_gap = 50;                 // positives need the trajectory frame indices more than this apart
  int negatives_per_positive = 10;  // SSC's "neg_N"
  int min_negatives = 100;          // at least this many negatives (when that many exist)
  std::uint64_t seed = 0;           // negative sampling
};

struct LabelledPair {
  int query = 0;     // later frame
  int database = 0;  // earlier frame
  bool loop = false;
};

// Every positive pair, plus negatives sampled with a fixed seed. Sorted by (query, database).
std::vector<LabelledPair> distancePairs(const std::vector<Mat4d>& poses, const std::vector<int>& source,
                                        const PairListConfig& config);

struct LoopPose {
  int first = 0;                // earlier frame
  int second = 0;               // later frame
  Mat4d T = Mat4d::Identity();  // maps points of `first` into the LiDAR frame of `second`: p_second = T * p_first
};

// Every pair whose 3-D distance is below max_distance and whose trajectory indices are more than min_gap
// apart, with the exact relative pose (LCR-Net loop_distance4 convention). Sorted by (second, first).
std::vector<LoopPose> loopPoses(const std::vector<Mat4d>& poses, const std::vector<int>& source,
                                double max_distance = 4.0, int min_gap = 50);

struct OdometryNoise {
  double translation = 0.0;         // sigma per axis, as a fraction of the distance travelled per step
  double rotation_deg_per_m = 0.0;  // yaw sigma per metre travelled (roll/pitch get a fifth of it)
  bool any() const { return translation > 0 || rotation_deg_per_m > 0; }
};

// Odometry: starts at poses[0] and integrates the true relative motion between consecutive output frames,
// each step perturbed by noise seeded by (seed, source index), so the error random-walks (drift).
std::vector<Mat4d> driftingOdometry(const std::vector<Mat4d>& poses, const std::vector<int>& source,
                                    const OdometryNoise& noise, std::uint64_t seed);

// Relative yaw (deg, in [0, 180]) between two poses' forward (x) axes, in the world's horizontal plane.
double headingDifferenceDeg(const Mat4d& a, const Mat4d& b);

}  // namespace sglc::sim
