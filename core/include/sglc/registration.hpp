// Rigid registration: closed-form fit, deterministic RANSAC over node matches, instance ICP, and the
// point-to-plane refinement on background planes.
#pragma once

#include <vector>

#include "sglc/background.hpp"
#include "sglc/config.hpp"
#include "sglc/matching.hpp"
#include "sglc/plane_index.hpp"
#include "sglc/types.hpp"

namespace sglc {

// Least-squares rigid transform T with dst ~= T * src (Kabsch/Umeyama, reflection-safe). Needs >= 3 points.
Mat4d fitRigid(const std::vector<Vec3d>& src, const std::vector<Vec3d>& dst);

struct RansacResult {
  bool found = false;
  Mat4d T = Mat4d::Identity();  // maps candidate points into the query frame
  std::vector<int> inliers;     // indices into the match list, ascending
  double mean_residual = 0.0;   // over inliers (m), after refitting on them
};

// query[i] ~ T * candidate[i]. Every triple is tried when there are at most max_iterations of them, otherwise
// a seeded sample. Degenerate (near-collinear) samples are skipped.
RansacResult ransacRigid(const std::vector<Vec3d>& query, const std::vector<Vec3d>& candidate,
                         const RansacConfig& config);

// Instance points of one node, a view into a fingerprint's storage.
struct InstanceView {
  const Vec3f* points = nullptr;
  int size = 0;
};

struct IcpResult {
  Mat4d T = Mat4d::Identity();
  int iterations = 0;
  int correspondences = 0;
  double rmse = 0.0;                           // over the final correspondences (m)
  double fitness = 0.0;                        // share of candidate instance points with a correspondence
  std::vector<std::pair<Vec3f, Vec3f>> pairs;  // final (query point, candidate point) correspondences
};

// Point-to-point ICP restricted to matched instances: a candidate point of instance j only pairs with the
// nearest point of the query instance matched to j. Huber-weighted, correspondence gate shrinking.
IcpResult icpInstances(const std::vector<std::pair<InstanceView, InstanceView>>& instances, const Mat4d& T0,
                       const FineConfig& config);

struct RefineResult {
  Mat4d T = Mat4d::Identity();
  int iterations = 0;
  int correspondences = 0;  // plane pairs at the final pose
  double rmse = 0.0;        // point-to-plane, over correspondences (m)
  double fitness = 0.0;     // share of candidate planes with a consistent query plane
  // Fisher information of T at the final pose (zero when the stage did not run): residuals weighted by
  // 1 / max(rmse, 1 cm)^2, over a right perturbation T_true = T exp(xi), xi = (translation, rotation) in the
  // candidate's frame (metres, radians).
  Mat6d information = Mat6d::Zero();
  // How firmly the planes alone fix the pose on the ground: the smallest eigenvalue of their Gauss-Newton
  // Hessian over heading and horizontal shift (Cauchy-weighted plane pairs, heading scaled by a 10 m lever arm;
  // 1/m^2, about the number of plane pairs whose normals pin the weakest direction). A straight corridor leaves
  // the shift along it free: near 0. It is the Hessian's block with roll, pitch and height held (not their
  // Schur complement), and it grows with the number of planes, so thresholds on it assume the default
  // fingerprint.plane_voxel_m.
  double horizontal_constraint = 0.0;
  // The next smallest eigenvalue of that Hessian: at least as large; both small when the planes leave two
  // directions free.
  double next_constraint = 0.0;
  // The weakest direction as a motion of the candidate in the query frame: a shift (unit, horizontal) along the
  // corridor, with weak_turn radians of heading about the query's origin per metre of it (a curved street's
  // free motion turns as it shifts). Zero when the constraint was not computed, or when the weakest direction is
  // mostly a turn.
  Vec2d weak_shift = Vec2d::Zero();
  double weak_turn = 0.0;
};

// Point-to-plane alignment of the candidate's plane centroids onto the query's planes (re-associated each
// round, Cauchy-weighted), with the instance correspondences of the fine stage as an anchor so that
// directions the planes leave free (a straight corridor) stay where the instances put them. The anchor acts
// only in those directions (Hessian eigenvalues below config.min_information): elsewhere instance pairs,
// which join differently sampled sides of the same objects, would bias the pose the planes fix.
// Information of T from point pairs (query point, candidate point), as RefineResult::information.
Mat6d pointPairInformation(const std::vector<std::pair<Vec3f, Vec3f>>& pairs, const Mat4d& T, double rmse);

RefineResult refinePlanes(const std::vector<Plane>& query, const PlaneIndex& query_index,
                          const std::vector<Plane>& candidate, const std::vector<std::pair<Vec3f, Vec3f>>& anchor_pairs,
                          const Mat4d& T0, const RefineConfig& config);

}  // namespace sglc
