// Loop-closure metrics, defined as in docs/METHOD.md so that numbers compare with published ones.
// Pure functions over plain values; no I/O.
#pragma once

#include <cstddef>
#include <vector>

#include "sglc/types.hpp"

namespace sglc::eval {

// One scored decision: a pair (pair protocol) or a query's best candidate (sequence protocol).
//   predicted_true: the candidate is a true loop (pair label 1 / top-1 candidate within the positive radius)
//   has_true_loop:  a true loop exists for this query (pair protocol: same as predicted_true)
// A decision counts as a detection at threshold t when score >= t. At threshold t:
//   TP = detections with predicted_true; FP = detections without;
//   FN = decisions with has_true_loop that are not a TP (missed, or the detection was a wrong candidate).
struct Decision {
  double score = 0;
  bool predicted_true = false;
  bool has_true_loop = false;
};

// The precision-recall curve in the manner of sklearn's precision_recall_curve: one point per distinct score
// (thresholds ascending), precision = TP / (TP + FP), recall = TP / (TP + FN). Points with no detection
// (TP + FP = 0) are left out. With no positives at all (TP + FN = 0 everywhere) recall is 0.
struct PrPoint {
  double threshold = 0;
  double precision = 0;
  double recall = 0;
  std::size_t tp = 0, fp = 0, fn = 0;
};
std::vector<PrPoint> prCurve(const std::vector<Decision>& decisions);

// Max over the curve of 2PR / (P + R) (0 for an empty curve or P + R = 0 everywhere), and its threshold.
struct F1Max {
  double f1 = 0;
  double threshold = 0;
  double precision = 0;
  double recall = 0;
};
F1Max f1Max(const std::vector<PrPoint>& curve);

// Extended precision: (precision at the lowest recall point of the curve + the largest recall reached at
// precision 1) / 2. The lowest-recall point is the one with the highest threshold. 0 for an empty curve.
double extendedPrecision(const std::vector<PrPoint>& curve);

// Area under the PR curve (recall on x): trapezoids between consecutive points sorted by recall, starting
// from (recall 0, precision of the lowest-recall point). 0 for an empty curve.
double prAuc(const std::vector<PrPoint>& curve);

// Recall@N: among queries with a true loop, the share whose first N ranked candidates contain a true one.
// ranked_true[q][r] says whether query q's r-th candidate is a true loop; queries without a true loop are
// skipped. 0 when no query has a true loop.
double recallAtN(const std::vector<std::vector<bool>>& ranked_true, const std::vector<bool>& has_true_loop,
                 std::size_t n);

// Pose errors of an estimate against ground truth (both 4x4 rigid transforms).
// RTE = |t_gt - t_est| (m); RRE = acos((trace(R_est^T R_gt) - 1) / 2) in degrees (argument clamped to [-1, 1]).
struct PoseError {
  double rte_m = 0;
  double rre_deg = 0;
};
PoseError poseError(const Mat4d& estimate, const Mat4d& ground_truth);

// Registration recall: share of pairs with RTE < max_rte and RRE < max_rre (a failed registration is passed
// as std::nullopt-like `registered = false`); mean RTE / RRE over the successful pairs only.
struct RegistrationResult {
  bool registered = false;  // false: no pose was produced (counts as a failure)
  PoseError error;
  bool verified = false;  // verification accepted the pair as a loop
};
struct RegistrationSummary {
  std::size_t pairs = 0, successes = 0;
  double rr = 0;                      // successes / pairs (0 for no pairs)
  double rr_verified = 0;             // successes that verification also accepted / pairs
  double rte_mean = 0, rre_mean = 0;  // over successes (0 if none)
  double rte_median = 0, rre_median = 0;
};
RegistrationSummary registrationRecall(const std::vector<RegistrationResult>& results, double max_rte_m = 2.0,
                                       double max_rre_deg = 5.0);

}  // namespace sglc::eval

namespace sglc::eval {

// Absolute trajectory error: RMSE of positions after the best rigid alignment (rotation + translation, no
// scale; Umeyama) of the estimate onto ground truth. `aligned`, if given, receives the aligned estimate
// positions. Throws InputError on empty or different-size inputs.
double absoluteTrajectoryError(const std::vector<Mat4d>& estimate, const std::vector<Mat4d>& ground_truth,
                               std::vector<Eigen::Vector3d>* aligned = nullptr);

}  // namespace sglc::eval
