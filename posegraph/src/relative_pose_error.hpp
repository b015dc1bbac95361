// The pose graph's edge: a relative-pose measurement between two nodes, whitened by its information.
#pragma once

#include <algorithm>
#include <optional>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "sglc/types.hpp"

namespace ceres {
class CostFunction;
}

namespace sglc::posegraph {

// Residual of a relative-pose measurement T_ab (maps b's points into a's frame) between poses a and b (both
// scan -> map): translation and rotation of inv(T_ab) * inv(T_a) * T_b, i.e. the right perturbation
// (translation first) that takes T_ab to the predicted relative pose, whitened by an upper-triangular square
// root of the edge's information (information = sqrt_info' * sqrt_info).
struct RelativePoseError {
  Eigen::Quaterniond q_ab;
  Eigen::Vector3d t_ab;
  Mat6d sqrt_info;
  // A pose is 7 numbers: quaternion x, y, z, w, then translation.
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    Eigen::Map<const Eigen::Quaternion<T>> qa(a), qb(b);
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> ta(a + 4), tb(b + 4);
    const Eigen::Quaternion<T> qa_inv = qa.conjugate();
    const Eigen::Quaternion<T> q_pred = qa_inv * qb;
    const Eigen::Matrix<T, 3, 1> t_pred = qa_inv * (tb - ta);
    const Eigen::Quaternion<T> dq = q_ab.template cast<T>().conjugate() * q_pred;
    Eigen::Matrix<T, 6, 1> e;
    e.template head<3>() = q_ab.template cast<T>().conjugate() * (t_pred - t_ab.template cast<T>());
    e.template tail<3>() = T(2.0) * dq.vec();
    Eigen::Map<Eigen::Matrix<T, 6, 1>> out(r);
    out = sqrt_info.template cast<T>() * e;
    return true;
  }  // The whitened error at poses a and b, squared.
  double squaredError(const double* a, const double* b) const {
    Eigen::Matrix<double, 6, 1> r;
    (*this)(a, b, r.data());
    return r.squaredNorm();
  }
};

inline RelativePoseError relativePoseError(const Eigen::Matrix4d& T_ab, const Mat6d& sqrt_info) {
  return RelativePoseError{Eigen::Quaterniond(T_ab.block<3, 3>(0, 0)).normalized(), T_ab.block<3, 1>(0, 3), sqrt_info};
}

inline Mat6d diagonalSqrtInformation(double sigma_t, double sigma_r) {
  Mat6d S = Mat6d::Zero();
  S.diagonal() << 1 / sigma_t, 1 / sigma_t, 1 / sigma_t, 1 / sigma_r, 1 / sigma_r, 1 / sigma_r;
  return S;
}

// A loop's registration information, with a floor covariance added (no registration is better than its model:
// planes are not perfectly flat, labels not perfectly right), as an upper-triangular square root.
inline Mat6d loopSqrtInformation(const Mat6d& information, double floor_t, double floor_r) {
  const Eigen::SelfAdjointEigenSolver<Mat6d> eig(0.5 * (information + information.transpose()));
  Eigen::Matrix<double, 6, 1> var;
  for (int k = 0; k < 6; ++k) var[k] = 1.0 / std::max(eig.eigenvalues()[k], 1e-12);  // free directions: huge
  Mat6d cov = eig.eigenvectors() * var.asDiagonal() * eig.eigenvectors().transpose();
  cov.diagonal().head<3>().array() += floor_t * floor_t;
  cov.diagonal().tail<3>().array() += floor_r * floor_r;
  const Mat6d info = cov.inverse();
  return Eigen::LLT<Mat6d>(0.5 * (info + info.transpose())).matrixU();
}

inline constexpr double kRadPerDeg = 3.14159265358979323846 / 180.0;

// An odometry step's edge weight: per-axis sigmas growing with the distance driven (GraphOptimiserOptions).
inline Mat6d odometrySqrtInformation(const Mat4d& step, double sigma_m, double sigma_per_m, double sigma_deg,
                                     double sigma_deg_per_m) {
  const double d = step.block<3, 1>(0, 3).norm();
  return diagonalSqrtInformation(sigma_m + sigma_per_m * d, (sigma_deg + sigma_deg_per_m * d) * kRadPerDeg);
}

// A loop's edge weight: the registration's information plus a floor covariance, or (loops recorded without
// one) a sigma from the refinement's residual, at least the floor.
inline Mat6d loopEdgeSqrtInformation(const std::optional<Mat6d>& information, double rmse, double sigma_m,
                                     double sigma_deg) {
  const double floor_r = sigma_deg * kRadPerDeg;
  if (information) return loopSqrtInformation(*information, sigma_m, floor_r);
  const double st = std::max(sigma_m, rmse);
  return diagonalSqrtInformation(st, floor_r * st / sigma_m);
}

// The edge as an automatically differentiated Ceres cost (owned by the problem it is added to). Compiled in a
// unit of its own (relative_pose_error.cpp): there GCC inlines the whole dual-number evaluation, which it
// stops doing inside a large unit.
ceres::CostFunction* relativePoseCost(const RelativePoseError& e);

}  // namespace sglc::posegraph
