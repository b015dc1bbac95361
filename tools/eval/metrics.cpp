#include "metrics.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>

namespace sglc::eval {

std::vector<PrPoint> prCurve(const std::vector<Decision>& decisions) {
  struct Ranked {
    double score;
    bool predicted_true, has_true_loop;
  };
  std::size_t positives = 0;  // decisions with has_true_loop: TP + FN at every threshold
  std::vector<Ranked> ranked;
  ranked.reserve(decisions.size());
  for (const auto& d : decisions) {
    positives += d.has_true_loop;
    // score >= t is false for a NaN score whatever t is: never a detection, and no threshold of its own.
    if (!std::isnan(d.score)) ranked.push_back({d.score, d.predicted_true, d.has_true_loop});
  }
  std::sort(ranked.begin(), ranked.end(), [](const Ranked& a, const Ranked& b) { return a.score > b.score; });

  // Sweep thresholds from the highest score down; a group of equal scores becomes detections together, so
  // every point has TP + FP >= 1 and the counts do not depend on the order of ties.
  std::vector<PrPoint> curve;
  std::size_t tp = 0, fp = 0, tp_with_true_loop = 0;
  for (std::size_t i = 0; i < ranked.size();) {
    const double t = ranked[i].score;
    for (; i < ranked.size() && ranked[i].score == t; ++i) {
      if (ranked[i].predicted_true) {
        ++tp;
        tp_with_true_loop += ranked[i].has_true_loop;
      } else {
        ++fp;
      }
    }
    PrPoint p;
    p.threshold = t + 0.0;  // -0.0 and 0.0 tie; report +0.0 whichever of them sorted first
    p.tp = tp;
    p.fp = fp;
    p.fn = positives - tp_with_true_loop;
    p.precision = static_cast<double>(tp) / static_cast<double>(tp + fp);
    p.recall = tp + p.fn > 0 ? static_cast<double>(tp) / static_cast<double>(tp + p.fn) : 0.0;
    curve.push_back(p);
  }
  std::reverse(curve.begin(), curve.end());
  return curve;
}

// Ties keep the first point in curve order: the lowest threshold for prCurve's ascending output.
F1Max f1Max(const std::vector<PrPoint>& curve) {
  F1Max best;
  for (const auto& p : curve) {
    const double sum = p.precision + p.recall;
    const double f1 = sum > 0 ? 2 * p.precision * p.recall / sum : 0.0;
    if (f1 > best.f1) best = {f1, p.threshold, p.precision, p.recall};
  }
  return best;
}

double extendedPrecision(const std::vector<PrPoint>& curve) {
  if (curve.empty()) return 0;
  const auto lowest_recall = std::max_element(
      curve.begin(), curve.end(), [](const PrPoint& a, const PrPoint& b) { return a.threshold < b.threshold; });
  double recall_at_p1 = 0;
  for (const auto& p : curve)
    if (p.precision >= 1) recall_at_p1 = std::max(recall_at_p1, p.recall);
  return (lowest_recall->precision + recall_at_p1) / 2;
}

double prAuc(const std::vector<PrPoint>& curve) {
  if (curve.empty()) return 0;
  // Points of equal recall keep the order of a sweep from high to low threshold; the area depends on it.
  std::vector<const PrPoint*> pts;
  pts.reserve(curve.size());
  for (const auto& p : curve) pts.push_back(&p);
  std::stable_sort(pts.begin(), pts.end(), [](const PrPoint* a, const PrPoint* b) {
    return a->recall != b->recall ? a->recall < b->recall : a->threshold > b->threshold;
  });
  double area = 0, recall = 0, precision = pts.front()->precision;
  for (const auto* p : pts) {
    area += (p->recall - recall) * (p->precision + precision) / 2;
    recall = p->recall;
    precision = p->precision;
  }
  return area;
}

double recallAtN(const std::vector<std::vector<bool>>& ranked_true, const std::vector<bool>& has_true_loop,
                 std::size_t n) {
  if (ranked_true.size() != has_true_loop.size())
    throw std::invalid_argument("recallAtN: " + std::to_string(ranked_true.size()) + " ranked lists for " +
                                std::to_string(has_true_loop.size()) + " queries");
  std::size_t queries = 0, hits = 0;
  for (std::size_t q = 0; q < ranked_true.size(); ++q) {
    if (!has_true_loop[q]) continue;
    ++queries;
    const auto& r = ranked_true[q];
    const auto end = r.begin() + static_cast<std::ptrdiff_t>(std::min(n, r.size()));
    hits += std::find(r.begin(), end, true) != end;
  }
  return queries > 0 ? static_cast<double>(hits) / static_cast<double>(queries) : 0.0;
}

PoseError poseError(const Mat4d& estimate, const Mat4d& ground_truth) {
  const Mat3d r_est = estimate.topLeftCorner<3, 3>();
  const Mat3d r_gt = ground_truth.topLeftCorner<3, 3>();
  // Rounding can put the cosine of a near-zero (or near-180 deg) angle just outside [-1, 1].
  const double cos_angle = std::clamp(((r_est.transpose() * r_gt).trace() - 1) / 2, -1.0, 1.0);
  PoseError e;
  e.rte_m = (ground_truth.topRightCorner<3, 1>() - estimate.topRightCorner<3, 1>()).norm();
  e.rre_deg = std::acos(cos_angle) * 180 / std::numbers::pi;
  return e;
}

namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 == 1 ? v[m] : (v[m - 1] + v[m]) / 2;
}

double mean(const std::vector<double>& v) {
  if (v.empty()) return 0;
  double sum = 0;
  for (double x : v) sum += x;
  return sum / static_cast<double>(v.size());
}

}  // namespace

RegistrationSummary registrationRecall(const std::vector<RegistrationResult>& results, double max_rte_m,
                                       double max_rre_deg) {
  std::vector<double> rte, rre;
  std::size_t verified = 0;
  for (const auto& r : results) {
    // Written as "<" so that a NaN error is a failure.
    if (r.registered && r.error.rte_m < max_rte_m && r.error.rre_deg < max_rre_deg) {
      rte.push_back(r.error.rte_m);
      rre.push_back(r.error.rre_deg);
      verified += r.verified;
    }
  }
  RegistrationSummary s;
  s.pairs = results.size();
  s.successes = rte.size();
  s.rr = s.pairs > 0 ? static_cast<double>(s.successes) / static_cast<double>(s.pairs) : 0.0;
  s.rr_verified = s.pairs > 0 ? static_cast<double>(verified) / static_cast<double>(s.pairs) : 0.0;
  s.rte_mean = mean(rte);
  s.rre_mean = mean(rre);
  s.rte_median = median(std::move(rte));
  s.rre_median = median(std::move(rre));
  return s;
}

}  // namespace sglc::eval

namespace sglc::eval {

double absoluteTrajectoryError(const std::vector<Mat4d>& estimate, const std::vector<Mat4d>& ground_truth,
                               std::vector<Eigen::Vector3d>* aligned) {
  if (estimate.empty() || estimate.size() != ground_truth.size())
    throw InputError("trajectory error needs two non-empty trajectories of the same length (got " +
                     std::to_string(estimate.size()) + " and " + std::to_string(ground_truth.size()) + ")");
  const auto n = static_cast<Eigen::Index>(estimate.size());
  Eigen::Matrix3Xd a(3, n), b(3, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    a.col(i) = estimate[static_cast<std::size_t>(i)].block<3, 1>(0, 3);
    b.col(i) = ground_truth[static_cast<std::size_t>(i)].block<3, 1>(0, 3);
  }
  const Eigen::Matrix4d T = n >= 3 ? Eigen::Matrix4d(Eigen::umeyama(a, b, false)) : Eigen::Matrix4d::Identity();
  const Eigen::Matrix3Xd moved = (T.block<3, 3>(0, 0) * a).colwise() + T.block<3, 1>(0, 3);
  if (aligned) {
    aligned->clear();
    for (Eigen::Index i = 0; i < n; ++i) aligned->push_back(moved.col(i));
  }
  return std::sqrt((moved - b).colwise().squaredNorm().mean());
}

}  // namespace sglc::eval
