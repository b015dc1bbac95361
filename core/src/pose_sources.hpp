// Where pose hypotheses come from (docs/METHOD.md, section 8): the landmarks (RANSAC over descriptor matches, or
// over pairs found by geometric consensus in small graphs) and the background (bird's-eye overlays at the
// walls' headings, or at a narrow view's context heading). Private to verification.cpp.
#pragma once

#include <vector>

#include "sglc/config.hpp"
#include "sglc/evidence.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/matching.hpp"

namespace sglc::detail {

struct LandmarkPose {
  PoseSource source = PoseSource::kNone;  // kNone: no pose
  Mat4d T = Mat4d::Identity();
  int matches = 0;  // node matches after pruning (or consensus pairs)
  int inliers = 0;
  double graph_similarity = 0.0;    // exp(-mean inlier residual)
  std::vector<Match> inlier_pairs;  // (query node, candidate node), for the fine stage
  const char* failure = "";         // why there is no pose
};
LandmarkPose landmarkPose(const Fingerprint& query, const Fingerprint& candidate, const Config& config);

// Overlay poses of the background views, best first: at the walls' headings (full views), or at the view
// context's heading with ViewSearchConfig::shifts_per_heading (3) shifts per heading step (narrow pairs). Empty
// when the views share no structure or heading.
std::vector<Mat4d> overlayPoses(const Fingerprint& query, const Fingerprint& candidate, const PairView& view,
                                const Config& config);

}  // namespace sglc::detail
