// The evidence for a loop, measured the same way for every pose hypothesis (docs/METHOD.md, section 7): what
// the landmarks, the background's bird's-eye view, its planes and the view context say about a candidate pose
// T_q_c. The loop decision is one model over this record (sglc/loop_model.hpp); nothing else decides.
#pragma once

#include <cstdint>
#include <string>

#include "sglc/config.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/types.hpp"

namespace sglc {

// Where a pose hypothesis came from.
enum class PoseSource : std::uint8_t {
  kNone = 0,       // no hypothesis (no pose to judge)
  kLandmarks,      // RANSAC over descriptor-matched landmarks
  kConsensus,      // RANSAC over landmarks paired by geometry (small graphs)
  kWallHeadings,   // bird's-eye overlay at the headings the walls give
  kViewHeadings,   // bird's-eye overlay at the heading the view context gives (a narrow view)
};
const char* poseSourceName(PoseSource source);  // "landmarks", "consensus", "walls", "view", "none"

struct Evidence {
  PoseSource source = PoseSource::kNone;
  // Landmarks: nodes of one class paired one to one within the landmark gate on the ground at the pose, and
  // exp(-mean distance of those pairs) (0 with none).
  int landmarks = 0;
  double landmark_similarity = 0.0;
  // How much of the horizon the scan that saw less saw (degrees, 0-360; viewSpanDeg): the field every
  // agreement below is judged over.
  double field_deg = 0.0;
  // Background agreement over that field: near (+-25 m, 2 m cells) and wide (+-45 m, 1 m cells).
  double agreement = 0.0;
  double wide_agreement = 0.0;
  // How much lower the near agreement is 2 and 4 m either way along the planes' weakest horizontal direction
  // (the smallest drop); positive: the bird's-eye view pins the pose along a corridor.
  double pin = 0.0;
  // The planes at the pose: band-plane overlap (share the scan with fewer explains), RMSE (m), and the
  // smallest eigenvalue of their horizontal information (1/m^2; about the number of planes pinning the
  // weakest direction).
  double plane_overlap = 0.0;
  double plane_rmse_m = 0.0;
  double constraint = 0.0;
  // The view contexts' similarity at the pose's heading (the field of the scan that saw less).
  double context_similarity = 0.0;
  // |t| of the pose (m).
  double translation_m = 0.0;
};

}  // namespace sglc
