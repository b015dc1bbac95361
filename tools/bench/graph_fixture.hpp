// A map for pose-graph benchmarks: scans with placeholder fingerprints along an odometry trajectory, loops with
// a disturbed relative pose and the information to match, and the trajectory error of the optimised poses. Every
// draw comes from the simulator's generator (sim/rng.hpp), so a run repeats bit for bit on any library.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "sglc/descriptors.hpp"
#include "sglc/storage/map_store.hpp"
#include "sim/rng.hpp"

namespace sglc::bench {

// Loops' relative poses are disturbed by this much, and their information matrix says so.
inline constexpr double kLoopSigmaM = 0.05, kLoopSigmaRad = 0.1 * std::numbers::pi / 180.0;

// Positions' RMSE after the best rigid alignment.
inline double ate(const std::vector<Mat4d>& est, const std::vector<Mat4d>& gt) {
  Eigen::Matrix3Xd a(3, est.size()), b(3, gt.size());
  for (std::size_t i = 0; i < est.size(); ++i) {
    a.col(static_cast<Eigen::Index>(i)) = est[i].block<3, 1>(0, 3);
    b.col(static_cast<Eigen::Index>(i)) = gt[i].block<3, 1>(0, 3);
  }
  const Mat4d T = Eigen::umeyama(a, b, false);
  return std::sqrt(((T.block<3, 3>(0, 0) * a).colwise() + T.block<3, 1>(0, 3) - b).colwise().squaredNorm().mean());
}

inline Mat4d disturbed(const Mat4d& T, sim::Rng& rng, double sigma_m, double sigma_rad) {
  const Eigen::Vector3d w(sigma_rad * rng.normal(), sigma_rad * rng.normal(), sigma_rad * rng.normal());
  Mat4d E = Mat4d::Identity();
  if (w.norm() > 0) E.block<3, 3>(0, 0) = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
  E.block<3, 1>(0, 3) = Eigen::Vector3d(sigma_m * rng.normal(), sigma_m * rng.normal(), sigma_m * rng.normal());
  return T * E;
}

// A valid fingerprint with a random scan descriptor: the pose graph needs scans, not their content.
inline Fingerprint placeholder(sim::Rng& rng) {
  Fingerprint fp;
  fp.layout = DescriptorLayout{};
  fp.descriptor.resize(static_cast<std::size_t>(fp.layout.scanDim()));
  double norm = 0;
  for (auto& v : fp.descriptor) {
    v = static_cast<float>(rng.unit());
    norm += double(v) * v;
  }
  for (auto& v : fp.descriptor) v = static_cast<float>(v / std::sqrt(norm));
  fp.instance_offsets.assign(1, 0);
  fp.finalize();
  return fp;
}

// A SQLite map "m" in `dir` (synchronous=NORMAL: a benchmark needs no durability).
inline std::unique_ptr<storage::MapStore> openGraphStore(const std::string& dir) {
  storage::StoreOptions so;
  so.path = dir + "/graph.db";
  so.sync = storage::StoreOptions::Sync::kNormal;
  auto store = storage::MapStore::open(so);
  store->createMap("m", DescriptorLayout{}.scanDim());
  return store;
}

// Adds the first `count` odometry poses of `robot` (session "s") as scans; their ids.
inline std::vector<std::int64_t> addScans(storage::MapStore& store, const std::string& robot,
                                          const std::vector<Mat4d>& odometry, int count, sim::Rng& rng) {
  std::vector<std::int64_t> ids;
  for (int i = 0; i < count; ++i) {
    const auto fp = placeholder(rng);
    ids.push_back(store.addScan({.map = "m",
                                 .robot = robot,
                                 .session = "s",
                                 .seq = i,
                                 .odometry_pose = odometry[static_cast<std::size_t>(i)],
                                 .fingerprint = &fp}));
  }
  return ids;
}

// A loop whose information says its pose is good to sigma_m and sigma_rad per axis.
inline storage::LoopRecord loopRecord(std::int64_t query, std::int64_t candidate, const Mat4d& T, double sigma_m,
                                      double sigma_rad) {
  storage::LoopRecord r{0, query, candidate, T, 0.5, 0.9, sigma_m, 20};
  Mat6d info = Mat6d::Zero();
  info.diagonal() << 1 / (sigma_m * sigma_m), 1 / (sigma_m * sigma_m), 1 / (sigma_m * sigma_m),
      1 / (sigma_rad * sigma_rad), 1 / (sigma_rad * sigma_rad), 1 / (sigma_rad * sigma_rad);
  r.information = info;
  return r;
}

// The optimised poses of scans `ids` against the truth.
inline double ateOf(const storage::MapStore& store, const std::vector<std::int64_t>& ids,
                    const std::vector<Mat4d>& gt) {
  std::map<std::int64_t, Mat4d> opt;
  for (const auto& p : store.optimisedPoses("m", "", "", 0, std::numeric_limits<std::int64_t>::max()))
    opt[p.scan_id] = p.pose;
  std::vector<Mat4d> est;
  for (const auto id : ids) est.push_back(opt.at(id));
  return ate(est, gt);
}

}  // namespace sglc::bench
