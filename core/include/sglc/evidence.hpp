// The evidence for a loop, measured the same way for every pose hypothesis (docs/METHOD.md, section 8): what
// the landmarks, the background's bird's-eye view, its planes and the view context say about a candidate pose
// T_q_c. The loop decision is one model over this record (sglc/loop_model.hpp); nothing else decides.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "sglc/config.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/registration.hpp"
#include "sglc/types.hpp"
#include "sglc/view_context.hpp"

namespace sglc {

// Where a pose hypothesis came from.
enum class PoseSource : std::uint8_t {
  kNone = 0,      // no hypothesis (no pose to judge)
  kLandmarks,     // RANSAC over descriptor-matched landmarks
  kConsensus,     // RANSAC over landmarks paired by geometry (small graphs)
  kWallHeadings,  // bird's-eye overlay at the headings the walls give
  kViewHeadings,  // bird's-eye overlay at the heading the view context gives (a narrow view)
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
  // Whether the scan that saw less is a narrow view (field_deg under verify.background_min_view_deg).
  bool narrow = false;
};

// What two scans saw, measured once per pair: the field every agreement is judged over is the field of the scan
// that saw less. A full view (at least verify.background_min_view_deg of the horizon) is the whole field; a
// narrow one is its view context's field (ViewContext::field), and its context is compared with the other's.
struct PairView {
  bool narrow = false;
  // Both scans are narrow views: a view context is then matched against another wedge, not a full turn, and the
  // `view` source gives no hypotheses (the model was fitted on narrow scans against full ones only).
  bool both_narrow = false;
  bool query_saw_less = true;  // else the candidate saw less: its frame is where the field lies
  double field_deg = 360.0;
  std::vector<bool> field;  // empty: the whole field
  ViewMatch context;        // the narrow scan's context over the other's (narrow pairs only)
};
// What a pair's view needs of the query, computed once per query (Pipeline::viewRanking) rather than once per
// candidate: how much of the horizon it saw (negative: not known), and for a narrow query its view context and
// that context turned to every heading. Absent parts are computed from the fingerprint, and so is everything
// when `of` is not the query given (a view made for another scan is never used).
struct QueryView {
  const Fingerprint* of = nullptr;
  double span_deg = -1.0;
  const ViewContext* context = nullptr;
  const ViewMatcher* matcher = nullptr;
};
PairView pairView(const Fingerprint& query, const Fingerprint& candidate, const Config& config,
                  const QueryView& known = {});

// Background agreement (bevAgreement) at T_q_c over the pair's field, on a grid of `cell` metres out to
// `radius`, judged in the frame of the scan that saw less.
double fieldAgreement(const Fingerprint& query, const Fingerprint& candidate, const PairView& view, const Mat4d& T_q_c,
                      double cell, double radius);
// The record's `agreement`: fieldAgreement on 2 m cells within +-25 m.
double nearAgreement(const Fingerprint& query, const Fingerprint& candidate, const PairView& view, const Mat4d& T_q_c);

// The evidence at T_q_c. `planes` is the plane fit the pose came from (its T equal to T_q_c), or null when no
// fit was made: then the plane terms stay 0.
Evidence measureEvidence(const Fingerprint& query, const Fingerprint& candidate, const PairView& view,
                         PoseSource source, const Mat4d& T_q_c, const RefineResult* planes, const Config& config);

// Of the plane features in the height band both scans see (centroid at most max_z above the sensor), the share
// the scan with fewer has explained by the other under T_q_c (a sparse sensor's planes are matched against a
// dense one's without its missing planes counting against it).
double bandOverlap(const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T_q_c, double max_z,
                   const RefineConfig& config);

// Query landmarks paired one to one with a candidate node of their class within `gate` metres on the ground
// under T_q_c; `mean_distance` (optional) gets the mean ground distance of the pairs.
int landmarksAt(const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T_q_c, double gate,
                double* mean_distance = nullptr);

}  // namespace sglc
