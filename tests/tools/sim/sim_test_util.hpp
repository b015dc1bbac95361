// Shared helpers for the simulator tests: cached trajectories, small sensors, pose errors, temp dirs.
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>
#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <optional>
#include <set>
#include <string>
#include <system_error>
#include <vector>

#include "sim/simulator.hpp"

namespace sglc::sim::test {

inline std::string sharedData() { return SGLC_SHARED_DATA; }
inline std::string kittiPosesPath(const std::string& seq) {
  return sharedData() + "/kitti_odometry_gt_poses/poses/" + seq + ".txt";
}
// Sequences 00-02 share the Tr of the shared data's calib.txt; 04-10 share KITTI's other published Tr, kept
// in tools/sim/calib.
inline std::string kittiCalibPath(const std::string& seq) {
  if (seq >= "04") return std::string(SGLC_SIM_DIR) + "/calib/kitti-04-10-calib.txt";
  return sharedData() + "/semantickitti_scans/sequences/00/calib.txt";
}
inline bool haveKitti(const std::string& seq) {
  return std::filesystem::exists(kittiPosesPath(seq)) && std::filesystem::exists(kittiCalibPath(seq));
}
#define SGLC_REQUIRE_KITTI(seq)                                                            \
  if (!::sglc::sim::test::haveKitti(seq))                                                  \
  GTEST_SKIP() << "KITTI poses " << ::sglc::sim::test::kittiPosesPath(seq) << " or calib " \
               << ::sglc::sim::test::kittiCalibPath(seq) << " not found (shared data absent)"

inline const Trajectory& loopTrajectory() {
  static const Trajectory t = loopRoute();
  return t;
}
inline const Trajectory& kittiSequence(const std::string& seq) {
  static std::map<std::string, Trajectory> cache;
  auto it = cache.find(seq);
  if (it == cache.end()) it = cache.emplace(seq, loadKittiTrajectory(kittiPosesPath(seq), kittiCalibPath(seq))).first;
  return it->second;
}

// A small sensor (fast under sanitizers): 16 beams over the HDL-64's field of view, 360 columns.
inline SensorConfig smallSensor() {
  SensorConfig s = SensorConfig::preset(16);
  s.columns = 360;
  return s;
}

inline SimConfig smallConfig(std::uint64_t seed = 7) {
  SimConfig c;
  c.seed = seed;
  c.sensor = smallSensor();
  return c;
}

inline double translationError(const Mat4d& A, const Mat4d& B) {
  return (A.topRightCorner<3, 1>() - B.topRightCorner<3, 1>()).norm();
}
inline double rotationErrorDeg(const Mat4d& A, const Mat4d& B) {
  const Mat3d R = A.topLeftCorner<3, 3>().transpose() * B.topLeftCorner<3, 3>();
  return std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

// Instance ids (raw label, class + instance) of landmark classes with at least min_points points.
inline std::set<std::uint32_t> landmarkInstances(const Frame& f, int min_points) {
  std::map<std::uint32_t, int> count;
  for (auto l : f.scan.labels) {
    const std::uint32_t cls = l & 0xFFFFu;
    if ((cls == 10 || cls == 18 || cls == 20 || cls == 71 || cls == 80) && (l >> 16) != 0) ++count[l];
  }
  std::set<std::uint32_t> out;
  for (const auto& [l, n] : count)
    if (n >= min_points) out.insert(l);
  return out;
}

// A fresh directory under the system temp dir, removed on destruction.
class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    path_ = std::filesystem::temp_directory_path() /
            ("sglc_sim_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

inline std::string readFile(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace sglc::sim::test
