#include "sglc/registration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>

namespace sglc {
namespace {

// Residual sigmas below this (m) are not trusted when turning a fit into an information matrix.
constexpr double kMinResidualSigma = 0.01;

// Weighted closed-form rigid fit: dst ~= R * src + t (Kabsch with the reflection fix).
template <typename GetSrc, typename GetDst, typename GetW>
Mat4d weightedFit(std::size_t n, GetSrc src, GetDst dst, GetW weight) {
  double wsum = 0;
  Vec3d cs = Vec3d::Zero(), cd = Vec3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const double w = weight(i);
    wsum += w;
    cs += w * src(i);
    cd += w * dst(i);
  }
  Mat4d T = Mat4d::Identity();
  if (wsum <= 0) return T;
  cs /= wsum;
  cd /= wsum;
  Mat3d H = Mat3d::Zero();
  for (std::size_t i = 0; i < n; ++i) H += weight(i) * (src(i) - cs) * (dst(i) - cd).transpose();
  const Eigen::JacobiSVD<Mat3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3d D = Mat3d::Identity();
  if ((svd.matrixV() * svd.matrixU().transpose()).determinant() < 0) D(2, 2) = -1;
  const Mat3d R = svd.matrixV() * D * svd.matrixU().transpose();
  T.topLeftCorner<3, 3>() = R;
  T.topRightCorner<3, 1>() = cd - R * cs;
  return T;
}

// Twice the triangle's area over its longest side: its smallest height.
double triangleHeight(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const double longest = std::max({(a - b).norm(), (b - c).norm(), (c - a).norm()});
  if (longest <= 0) return 0;
  return (b - a).cross(c - a).norm() / longest;
}

// splitmix64: a tiny, portable, seeded generator (std distributions differ between standard libraries).
struct SplitMix {
  std::uint64_t state;
  std::uint64_t next() {
    std::uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  int below(int n) { return static_cast<int>(next() % static_cast<std::uint64_t>(n)); }
};

// Orthonormal frame of a triangle: x along a->b, z normal to the triangle (caller ensures it is not flat).
Mat3d triad(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  Mat3d F;
  const Vec3d x = (b - a).normalized();
  const Vec3d z = x.cross(c - a).normalized();
  F << x, z.cross(x), z;
  return F;
}

// Rigid motion taking triangle (a, b, c) onto (qa, qb, qc): frames aligned, centroids matched. A cheap
// hypothesis for RANSAC (the winner is refitted by least squares on its inliers).
Mat4d triadPose(const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& qa, const Vec3d& qb, const Vec3d& qc) {
  const Mat3d R = triad(qa, qb, qc) * triad(a, b, c).transpose();
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = R;
  T.topRightCorner<3, 1>() = (qa + qb + qc) / 3.0 - R * (a + b + c) / 3.0;
  return T;
}

Mat4d expSE3(const Eigen::Matrix<double, 6, 1>& d) {
  Mat4d T = Mat4d::Identity();
  const Vec3d w = d.head<3>();
  const double angle = w.norm();
  if (angle > 0) T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
  T.topRightCorner<3, 1>() = d.tail<3>();
  return T;
}

// Information of a left perturbation (omega, v) of T, T' = exp(d) T, expressed for a right perturbation
// (rho, phi), T' = T exp(xi), translation first: with d = M xi, omega = R phi and v = R rho + [t]x R phi.
Mat6d rightInformation(const Mat6d& left, const Mat4d& T) {
  const Mat3d R = T.topLeftCorner<3, 3>();
  const Vec3d t = T.topRightCorner<3, 1>();
  Mat3d tx;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  Mat6d M = Mat6d::Zero();
  M.block<3, 3>(0, 3) = R;
  M.block<3, 3>(3, 0) = R;
  M.block<3, 3>(3, 3) = tx * R;
  return M.transpose() * left * M;
}

// Gauss-Newton terms of point pairs (query point, candidate point) at T, for a left perturbation (rotation
// first): H += w J'J, g += w J'r with r = T * candidate - query and J = d(T * candidate)/d(omega, v).
void addPointPairs(const std::vector<std::pair<Vec3f, Vec3f>>& pairs, const Mat4d& T, double w, Mat6d& H,
                   Eigen::Matrix<double, 6, 1>& g) {
  const Mat3d R = T.topLeftCorner<3, 3>();
  const Vec3d t = T.topRightCorner<3, 1>();
  for (const auto& [qp, cp] : pairs) {
    const Vec3d x = R * cp.cast<double>() + t;
    Eigen::Matrix<double, 3, 6> J;
    J.leftCols<3>() << 0, x.z(), -x.y(), -x.z(), 0, x.x(), x.y(), -x.x(), 0;  // -[x]_x
    J.rightCols<3>().setIdentity();
    H += w * J.transpose() * J;
    g += w * J.transpose() * (x - qp.cast<double>());
  }
}

}  // namespace

Mat6d pointPairInformation(const std::vector<std::pair<Vec3f, Vec3f>>& pairs, const Mat4d& T, double rmse) {
  Mat6d H = Mat6d::Zero();
  Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
  addPointPairs(pairs, T, 1.0, H, g);
  const double sigma = std::max(rmse, kMinResidualSigma);
  return rightInformation(H / (sigma * sigma), T);
}

Mat4d fitRigid(const std::vector<Vec3d>& src, const std::vector<Vec3d>& dst) {
  return weightedFit(
      src.size(), [&](std::size_t i) { return src[i]; }, [&](std::size_t i) { return dst[i]; },
      [](std::size_t) { return 1.0; });
}

namespace {

// Pairs whose candidate point lands within thr of its query point under T (their indices appended to `inliers`
// and their residuals summed into `residual_sum` where given).
int countPairInliers(const std::vector<Vec3d>& query, const std::vector<Vec3d>& candidate, const Mat4d& T, double thr,
                     std::vector<int>* inliers, double* residual_sum) {
  const Mat3d R = T.topLeftCorner<3, 3>();
  const Vec3d t = T.topRightCorner<3, 1>();
  int count = 0;
  double sum = 0;
  for (std::size_t k = 0; k < query.size(); ++k) {
    const double r = (R * candidate[k] + t - query[k]).norm();
    if (r < thr) {
      ++count;
      sum += r;
      if (inliers) inliers->push_back(static_cast<int>(k));
    }
  }
  if (residual_sum) *residual_sum = sum;
  return count;
}

}  // namespace

RansacResult ransacRigid(const std::vector<Vec3d>& query, const std::vector<Vec3d>& candidate,
                         const RansacConfig& config) {
  RansacResult best;
  const int n = static_cast<int>(query.size());
  if (n < 3 || static_cast<int>(candidate.size()) != n) return best;
  const double thr = config.inlier_threshold;

  auto countInliers = [&](const Mat4d& T, std::vector<int>* inliers, double* residual_sum) {
    return countPairInliers(query, candidate, T, thr, inliers, residual_sum);
  };

  int best_count = 0;
  double best_sum = std::numeric_limits<double>::max();
  Mat4d best_T = Mat4d::Identity();
  auto tryTriple = [&](int a, int b, int c) {
    // Rigid motions keep distances: reject samples whose side lengths disagree, and flat samples.
    const int idx[3] = {a, b, c};
    for (int s = 0; s < 3; ++s) {
      const int u = idx[s], v = idx[(s + 1) % 3];
      if (std::abs((query[u] - query[v]).norm() - (candidate[u] - candidate[v]).norm()) > 2 * thr) return;
    }
    if (triangleHeight(candidate[a], candidate[b], candidate[c]) < config.min_triangle_height ||
        triangleHeight(query[a], query[b], query[c]) < config.min_triangle_height)
      return;
    const Mat4d T = triadPose(candidate[a], candidate[b], candidate[c], query[a], query[b], query[c]);
    double sum = 0;
    const int count = countInliers(T, nullptr, &sum);
    if (count > best_count || (count == best_count && sum < best_sum)) {
      best_count = count;
      best_sum = sum;
      best_T = T;
    }
  };

  const double triples = static_cast<double>(n) * (n - 1) * (n - 2) / 6.0;
  if (triples <= config.max_iterations) {
    for (int a = 0; a < n; ++a)
      for (int b = a + 1; b < n; ++b)
        for (int c = b + 1; c < n; ++c) tryTriple(a, b, c);
  } else {
    SplitMix rng{config.seed};
    for (int it = 0; it < config.max_iterations; ++it) {
      const int a = rng.below(n);
      int b = rng.below(n - 1);
      if (b >= a) ++b;
      int c = rng.below(n - 2);
      if (c >= std::min(a, b)) ++c;
      if (c >= std::max(a, b)) ++c;
      tryTriple(a, b, c);
    }
  }
  if (best_count < std::max(3, config.min_inliers)) return best;

  // Refit on the inliers until the set stops changing.
  std::vector<int> inliers;
  countInliers(best_T, &inliers, nullptr);
  for (int round = 0; round < 5; ++round) {
    const Mat4d T = weightedFit(
        inliers.size(), [&](std::size_t i) { return candidate[inliers[i]]; },
        [&](std::size_t i) { return query[inliers[i]]; }, [](std::size_t) { return 1.0; });
    std::vector<int> next;
    countInliers(T, &next, nullptr);
    if (static_cast<int>(next.size()) < static_cast<int>(inliers.size())) break;
    best_T = T;
    if (next == inliers) break;
    inliers = std::move(next);
  }
  best.found = true;
  best.T = best_T;
  best.inliers.clear();
  double sum = 0;
  countInliers(best_T, &best.inliers, &sum);
  if (static_cast<int>(best.inliers.size()) < std::max(3, config.min_inliers)) return RansacResult{};
  best.mean_residual = sum / static_cast<double>(best.inliers.size());
  return best;
}

namespace {

// Nearest of `sorted` (points sorted by x) to x closer than sqrt(best), or nullptr; best becomes its squared
// distance. Scans outwards from x.x() in both directions, stopping once |dx| alone exceeds the best distance.
const Vec3f* nearestByX(const std::vector<Vec3f>& sorted, const Vec3f& x, float& best) {
  const Vec3f* arg = nullptr;
  const auto mid =
      std::lower_bound(sorted.begin(), sorted.end(), x.x(), [](const Vec3f& u, float v) { return u.x() < v; });
  for (auto it = mid; it != sorted.end(); ++it) {
    const float dx = it->x() - x.x();
    if (dx * dx >= best) break;
    const float d2 = (*it - x).squaredNorm();
    if (d2 < best) {
      best = d2;
      arg = &*it;
    }
  }
  for (auto it = mid; it != sorted.begin();) {
    --it;
    const float dx = x.x() - it->x();
    if (dx * dx >= best) break;
    const float d2 = (*it - x).squaredNorm();
    if (d2 < best) {
      best = d2;
      arg = &*it;
    }
  }
  return arg;
}

}  // namespace

IcpResult icpInstances(const std::vector<std::pair<InstanceView, InstanceView>>& instances, const Mat4d& T0,
                       const FineConfig& config) {
  IcpResult result;
  result.T = T0;
  struct Corr {
    Vec3d q, p;
    double w;
  };
  std::vector<Corr> corr;
  std::size_t total = 0;
  for (const auto& [q, c] : instances) total += static_cast<std::size_t>(c.size);
  // Query instance points sorted by x: a nearest-neighbour search only scans the x-window of the gate.
  std::vector<std::vector<Vec3f>> sorted(instances.size());
  for (std::size_t k = 0; k < instances.size(); ++k) {
    const InstanceView& qv = instances[k].first;
    sorted[k].assign(qv.points, qv.points + qv.size);
    std::sort(sorted[k].begin(), sorted[k].end(), [](const Vec3f& u, const Vec3f& v) {
      return u.x() != v.x() ? u.x() < v.x() : (u.y() != v.y() ? u.y() < v.y() : u.z() < v.z());
    });
  }
  auto associate = [&](const Mat4d& T, double gate) {
    corr.clear();
    const Eigen::Matrix3f R = T.topLeftCorner<3, 3>().cast<float>();
    const Vec3f t = T.topRightCorner<3, 1>().cast<float>();
    const float gate2 = static_cast<float>(gate * gate);
    for (std::size_t k = 0; k < instances.size(); ++k) {
      const InstanceView& cv = instances[k].second;
      const std::vector<Vec3f>& qs = sorted[k];
      for (int i = 0; i < cv.size; ++i) {
        const Vec3f x = R * cv.points[i] + t;
        float best = gate2;
        const Vec3f* arg = nearestByX(qs, x, best);
        if (!arg) continue;
        const double r = std::sqrt(best);
        const double w = r <= config.huber_m ? 1.0 : config.huber_m / r;
        corr.push_back({arg->cast<double>(), cv.points[i].cast<double>(), w});
      }
    }
  };
  const int iters = config.max_iterations;
  for (int it = 0; it < iters; ++it) {
    const double frac = iters > 1 ? std::min(1.0, 3.0 * it / (iters - 1)) : 1.0;
    const double gate = config.max_corr_start_m + frac * (config.max_corr_end_m - config.max_corr_start_m);
    associate(result.T, gate);
    if (corr.size() < 3) break;
    const Mat4d T = weightedFit(
        corr.size(), [&](std::size_t i) { return corr[i].p; }, [&](std::size_t i) { return corr[i].q; },
        [&](std::size_t i) { return corr[i].w; });
    const double moved = (T.topRightCorner<3, 1>() - result.T.topRightCorner<3, 1>()).norm() +
                         (T.topLeftCorner<3, 3>() - result.T.topLeftCorner<3, 3>()).norm() * 10.0;
    result.T = T;
    result.iterations = it + 1;
    if (moved < config.converged_m && gate <= config.max_corr_end_m + 1e-9) break;
  }
  associate(result.T, config.max_corr_end_m);
  result.correspondences = static_cast<int>(corr.size());
  double sq = 0;
  const Mat3d R = result.T.topLeftCorner<3, 3>();
  const Vec3d t = result.T.topRightCorner<3, 1>();
  result.pairs.reserve(corr.size());
  for (const auto& c : corr) {
    sq += (R * c.p + t - c.q).squaredNorm();
    result.pairs.emplace_back(c.q.cast<float>(), c.p.cast<float>());
  }
  result.rmse = corr.empty() ? 0.0 : std::sqrt(sq / static_cast<double>(corr.size()));
  result.fitness = total ? static_cast<double>(corr.size()) / static_cast<double>(total) : 0.0;
  return result;
}

namespace {

using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;

// The instance pairs' normal equations added to the planes' (H, g at T; left perturbation, rotation first), acting
// only along horizontal directions (yaw, x, y) the planes leave (nearly) free: elsewhere the planes decide. Roll,
// pitch and height stay with the planes even where they are weak: the ground fixes them, while instance pairs (a
// car's points sampled differently from two viewpoints) tilt them. `scale` makes rotations and shifts compare.
void addWeakAnchor(const std::vector<std::pair<Vec3f, Vec3f>>& anchor_pairs, const Mat4d& T, const Vec6& scale,
                   const RefineConfig& config, Mat6& H, Vec6& g) {
  const double wa = config.instance_weight;
  if (wa <= 0 || anchor_pairs.empty()) return;
  const Mat6 Hs = scale.asDiagonal() * H * scale.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Mat3d> eig(Hs.block<3, 3>(2, 2));
  Mat6 P = Mat6::Zero();  // projector onto the weak horizontal subspace (scaled coordinates)
  for (int k = 0; k < 3; ++k)
    if (eig.eigenvalues()[k] < config.min_information)
      P.block<3, 3>(2, 2) += eig.eigenvectors().col(k) * eig.eigenvectors().col(k).transpose();
  if (P.isZero()) return;  // fully constrained: the pairs are not needed
  Mat6 Ha = Mat6::Zero();
  Vec6 ga = Vec6::Zero();
  addPointPairs(anchor_pairs, T, wa, Ha, ga);
  const Mat6 Has = scale.asDiagonal() * Ha * scale.asDiagonal();
  const Vec6 gas = scale.asDiagonal() * ga;
  // Back to unscaled coordinates: H += S^-1 P Has P S^-1, g += S^-1 P gas.
  const Vec6 inv = scale.cwiseInverse();
  H += inv.asDiagonal() * (P * Has * P) * inv.asDiagonal();
  g += inv.asDiagonal() * (P * gas);
}

// RefineResult's horizontal constraint, the next eigenvalue and the weakest direction, from the planes' Hessian
// over (heading, x, y) with the heading scaled by turn_scale (radians per scaled unit).
void setHorizontalConstraint(const Mat3d& Hg, double turn_scale, RefineResult& result) {
  const Eigen::SelfAdjointEigenSolver<Mat3d> weakest(Hg);
  result.horizontal_constraint = weakest.eigenvalues()[0];
  result.next_constraint = weakest.eigenvalues()[1];
  // (heading / scale, x, y) of a left perturbation: the shift is in the query frame, the turn about its origin.
  const Vec3d weak = weakest.eigenvectors().col(0);
  const Vec2d shift = weak.tail<2>();
  if (shift.norm() >= std::sqrt(0.5)) {
    result.weak_shift = shift.normalized();
    result.weak_turn = turn_scale * weak[0] / shift.norm();
  }
}

}  // namespace

RefineResult refinePlanes(const std::vector<Plane>& query, const PlaneIndex& query_index,
                          const std::vector<Plane>& candidate, const std::vector<std::pair<Vec3f, Vec3f>>& anchor_pairs,
                          const Mat4d& T0, const RefineConfig& config) {
  RefineResult result;
  result.T = T0;
  std::vector<int> assoc(candidate.size(), -1);
  auto associate = [&](const Mat4d& T) {
    const Eigen::Matrix3f R = T.topLeftCorner<3, 3>().cast<float>();
    const Vec3f t = T.topRightCorner<3, 1>().cast<float>();
    int count = 0;
    for (std::size_t k = 0; k < candidate.size(); ++k) {
      assoc[k] = query_index.nearest(query, R * candidate[k].centroid + t, R * candidate[k].normal, config.max_corr_m,
                                     config.min_normal_cosine);
      count += assoc[k] >= 0;
    }
    return count;
  };
  const double s2 = config.cauchy_m * config.cauchy_m;
  // Rotations are scaled by a lever arm so that eigenvalues of rotation and translation directions compare
  // (a rotation of 1/L rad moves a point L metres away by 1 m).
  constexpr double kLever = 10.0;
  Vec6 scale;
  scale << 1.0 / kLever, 1.0 / kLever, 1.0 / kLever, 1.0, 1.0, 1.0;
  // Gauss-Newton normal equations at T (left perturbation, rotation first) over the current association: the
  // planes' part, then the anchor's.
  auto planeEquations = [&](const Mat4d& T, Mat6& H, Vec6& g) {
    const Mat3d R = T.topLeftCorner<3, 3>();
    const Vec3d t = T.topRightCorner<3, 1>();
    H.setZero();
    g.setZero();
    for (std::size_t k = 0; k < candidate.size(); ++k) {
      if (assoc[k] < 0) continue;
      const Plane& q = query[assoc[k]];
      const Vec3d x = R * candidate[k].centroid.cast<double>() + t;
      const Vec3d nq = q.normal.cast<double>();
      const double r = nq.dot(x - q.centroid.cast<double>());
      const double w = 1.0 / (1.0 + r * r / s2);
      Vec6 J;
      J << x.cross(nq), nq;
      H += w * J * J.transpose();
      g += w * J * r;
    }
  };
  auto addAnchor = [&](const Mat4d& T, Mat6& H, Vec6& g) { addWeakAnchor(anchor_pairs, T, scale, config, H, g); };
  auto normalEquations = [&](const Mat4d& T, Mat6& H, Vec6& g) {
    planeEquations(T, H, g);
    addAnchor(T, H, g);
  };
  Mat6 H;
  Vec6 g;
  for (int it = 0; it < config.max_iterations; ++it) {
    if (associate(result.T) < 6) break;
    normalEquations(result.T, H, g);
    H.diagonal().array() += 1e-9 * (1.0 + H.trace());
    const Vec6 delta = -H.ldlt().solve(g);
    if (!delta.allFinite()) break;
    result.T = expSE3(delta) * result.T;
    result.iterations = it + 1;
    if (delta.tail<3>().norm() + delta.head<3>().norm() * 10.0 < config.converged_m) break;
  }
  result.correspondences = associate(result.T);
  double sq = 0;
  const Mat3d R = result.T.topLeftCorner<3, 3>();
  const Vec3d t = result.T.topRightCorner<3, 1>();
  for (std::size_t k = 0; k < candidate.size(); ++k) {
    if (assoc[k] < 0) continue;
    const Plane& q = query[assoc[k]];
    const double r =
        q.normal.cast<double>().dot(R * candidate[k].centroid.cast<double>() + t - q.centroid.cast<double>());
    sq += r * r;
  }
  result.rmse = result.correspondences ? std::sqrt(sq / result.correspondences) : 0.0;
  result.fitness = candidate.empty() ? 0.0 : static_cast<double>(result.correspondences) / candidate.size();
  if (result.iterations > 0 && result.correspondences >= 6) {
    // At the final pose and association: the planes alone (yaw, x, y are indices 2-4), then with the anchor.
    planeEquations(result.T, H, g);
    setHorizontalConstraint((scale.asDiagonal() * H * scale.asDiagonal()).block<3, 3>(2, 2), scale[2], result);
    addAnchor(result.T, H, g);
    const double sigma = std::max(result.rmse, kMinResidualSigma);
    result.information = rightInformation(H / (sigma * sigma), result.T);
  }
  return result;
}

}  // namespace sglc
