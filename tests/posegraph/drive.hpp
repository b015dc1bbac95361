// The pose-graph tests' drive: two laps of a 40 m circle with drifting odometry and exact loops between the laps,
// stored in a real map database; and the trajectory error they are judged by.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "../storage/storage_test_util.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::posegraph::testing {

inline Mat4d pose(double yaw, double x, double y) {
  Mat4d T = Mat4d::Identity();
  T.block<3, 3>(0, 0) = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T(0, 3) = x;
  T(1, 3) = y;
  return T;
}

// RMSE of positions after the best rigid alignment (Kabsch) of est onto gt.
inline double ate(const std::vector<Mat4d>& est, const std::vector<Mat4d>& gt) {
  Eigen::Matrix3Xd a(3, est.size()), b(3, gt.size());
  for (std::size_t i = 0; i < est.size(); ++i) {
    a.col(static_cast<Eigen::Index>(i)) = est[i].block<3, 1>(0, 3);
    b.col(static_cast<Eigen::Index>(i)) = gt[i].block<3, 1>(0, 3);
  }
  const Eigen::Matrix4d T = Eigen::umeyama(a, b, false);
  return std::sqrt(((T.block<3, 3>(0, 0) * a).colwise() + T.block<3, 1>(0, 3) - b).colwise().squaredNorm().mean());
}

struct Drive {
  std::vector<Mat4d> gt, odom;
  std::vector<std::int64_t> ids;
};

// Two laps of a 40 m circle, 120 scans per lap; odometry increments with noise (drift).
inline Drive drive(storage::MapStore& store) {
  store.createMap("m", DescriptorLayout{}.scanDim());
  Drive d;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n_t(0.0, 0.03), n_r(0.0, 0.001);  // per ~2 m step
  const int per_lap = 120;
  for (int i = 0; i < 2 * per_lap; ++i) {
    const double a = 2.0 * M_PI * i / per_lap;
    d.gt.push_back(pose(a + M_PI / 2, 40 * std::cos(a), 40 * std::sin(a)));
    if (i == 0) {
      d.odom.push_back(d.gt[0]);
    } else {
      const Mat4d step = d.gt[i - 1].inverse() * d.gt[i] * pose(n_r(rng), n_t(rng), n_t(rng));
      d.odom.push_back(d.odom.back() * step);
    }
    const auto fp = storage::testing::randomFingerprint(100 + i);
    storage::NewScan ns{
        .map = "m", .robot = "r", .session = "s", .seq = i, .odometry_pose = d.odom.back(), .fingerprint = &fp};
    d.ids.push_back(store.addScan(ns));
  }
  // Exact loops between the laps (query = second lap, candidate = first lap, T maps candidate into query).
  for (int i = per_lap + 5; i < 2 * per_lap; i += 3) {
    const int j = i - per_lap;
    store.addLoop("m", {0, d.ids[i], d.ids[j], d.gt[i].inverse() * d.gt[j], 0.8, 0.9, 0.02, 20});
  }
  return d;
}

// The optimiser's odometry model matching the drive's drift: 3 cm per axis and 0.057 deg per 2.1 m step.
inline GraphOptimiserOptions driveOptions() {
  GraphOptimiserOptions o;
  o.odometry_sigma_m = 0.0;
  o.odometry_sigma_per_m = 0.015;
  o.odometry_sigma_deg = 0.0;
  o.odometry_sigma_deg_per_m = 0.03;
  return o;
}

inline std::vector<Mat4d> optimised(const storage::MapStore& store) {
  std::vector<Mat4d> out;
  for (const auto& p : store.optimisedPoses("m", "", "", 0, 100000)) out.push_back(p.pose);
  return out;
}

}  // namespace sglc::posegraph::testing
