// Test-only reference registration: dense point-to-plane ICP over every static point of two real scans.
//
// The loop pose of ../shared/data/semantickitti_scans/pairs.txt comes from SemanticKITTI's trajectory, which is
// good to a few centimetres; the engine works from compact fingerprints. Aligning the two full scans (about
// 60k points each after a 15 cm thinning) from a close start gives an independent, sharper reference.
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "sglc/types.hpp"

namespace sglc::test {

class DenseRegistration {
 public:
  // Static structure only: no unlabelled/outlier points, vehicles (parked cars change between visits), persons,
  // or moving objects; 3-60 m from the sensor, one point per 15 cm voxel.
  static std::vector<Vec3d> staticPoints(const LabelledScan& scan) {
    std::vector<Vec3d> out;
    std::unordered_map<std::uint64_t, char> seen;
    for (std::size_t i = 0; i < scan.points.size(); ++i) {
      const std::uint32_t c = scan.labels[i] & 0xFFFFu;
      if (c <= 1 || (c >= 10 && c <= 32) || c >= 252) continue;
      const Vec3d p = scan.points[i].cast<double>();
      if (p.norm() < 3.0 || p.norm() > 60.0) continue;
      if (seen.emplace(key(p, 0.15), 1).second) out.push_back(p);
    }
    return out;
  }

  // `target` gets normals from its 0.5 m neighbourhoods.
  explicit DenseRegistration(std::vector<Vec3d> target) : target_(std::move(target)) {
    for (std::size_t i = 0; i < target_.size(); ++i) grid_[key(target_[i], kCell)].push_back(static_cast<int>(i));
    normal_.assign(target_.size(), Vec3d::Zero());
    planar_.assign(target_.size(), false);
    for (std::size_t i = 0; i < target_.size(); ++i) {
      Vec3d mean = Vec3d::Zero();
      std::vector<int> nb;
      around(target_[i], [&](int j) {
        if ((target_[j] - target_[i]).norm() < kCell) {
          nb.push_back(j);
          mean += target_[j];
        }
      });
      if (nb.size() < 6) continue;
      mean /= static_cast<double>(nb.size());
      Mat3d C = Mat3d::Zero();
      for (int j : nb) C += (target_[j] - mean) * (target_[j] - mean).transpose();
      const Eigen::SelfAdjointEigenSolver<Mat3d> eig(C / static_cast<double>(nb.size()));
      if (eig.eigenvalues()[0] > 0.02 * 0.02 || eig.eigenvalues()[1] < 4.0 * eig.eigenvalues()[0]) continue;
      normal_[i] = eig.eigenvectors().col(0);
      planar_[i] = true;
    }
  }

  // Aligns `source` onto the target from T0 (p_target = T * p_source), shrinking the correspondence gate.
  Mat4d align(const std::vector<Vec3d>& source, Mat4d T) const {
    using Vec6 = Eigen::Matrix<double, 6, 1>;
    for (double gate : {1.0, 0.5, 0.3, 0.2, 0.15, 0.1})
      for (int it = 0; it < 6; ++it) {
        Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
        Vec6 b = Vec6::Zero();
        const Mat3d R = T.topLeftCorner<3, 3>();
        const Vec3d t = T.topRightCorner<3, 1>();
        for (const auto& p : source) {
          const Vec3d x = R * p + t;
          double best = gate * gate;
          int arg = -1;
          around(x, [&](int j) {
            const double d = (target_[j] - x).squaredNorm();
            if (planar_[j] && d < best) {
              best = d;
              arg = j;
            }
          });
          if (arg < 0) continue;
          const Vec3d& n = normal_[static_cast<std::size_t>(arg)];
          const double r = n.dot(x - target_[static_cast<std::size_t>(arg)]);
          const double w = 1.0 / (1.0 + r * r / (0.05 * 0.05));
          Vec6 J;
          J << x.cross(n), n;
          H += w * J * J.transpose();
          b += w * J * r;
        }
        const Vec6 d = -H.ldlt().solve(b);
        Mat4d D = Mat4d::Identity();
        const double angle = d.head<3>().norm();
        if (angle > 0) D.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, d.head<3>() / angle).toRotationMatrix();
        D.topRightCorner<3, 1>() = d.tail<3>();
        T = D * T;
      }
    return T;
  }

 private:
  static constexpr double kCell = 0.5;
  static std::uint64_t key(const Vec3d& p, double cell) {
    const auto c = [&](double v) {
      return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(v / cell)) + (1 << 20)) & 0x1FFFFFu;
    };
    return (c(p.x()) << 42) | (c(p.y()) << 21) | c(p.z());
  }
  template <typename F>
  void around(const Vec3d& p, F f) const {
    const auto cx = static_cast<std::int64_t>(std::floor(p.x() / kCell)),
               cy = static_cast<std::int64_t>(std::floor(p.y() / kCell)),
               cz = static_cast<std::int64_t>(std::floor(p.z() / kCell));
    for (std::int64_t dx = -1; dx <= 1; ++dx)
      for (std::int64_t dy = -1; dy <= 1; ++dy)
        for (std::int64_t dz = -1; dz <= 1; ++dz) {
          const auto it =
              grid_.find(key(Vec3d((cx + dx + 0.5) * kCell, (cy + dy + 0.5) * kCell, (cz + dz + 0.5) * kCell), kCell));
          if (it == grid_.end()) continue;
          for (int j : it->second) f(j);
        }
  }

  std::vector<Vec3d> target_;
  std::vector<Vec3d> normal_;
  std::vector<bool> planar_;
  std::unordered_map<std::uint64_t, std::vector<int>> grid_;
};

}  // namespace sglc::test
