// The trajectory the benchmarks drive: KITTI 00's ground-truth path when the shared data is there, else the
// simulator's built-in loop route (so a benchmark runs anywhere, with its JSON naming which one it used).
#pragma once

#include <filesystem>
#include <string>

#include "sim/simulator.hpp"

namespace sglc::bench {

inline sim::Trajectory kitti00OrLoopRoute(const std::string& data_dir) {
  const auto poses = data_dir + "/kitti_odometry_gt_poses/poses/00.txt";
  const auto calib = data_dir + "/semantickitti_scans/sequences/00/calib.txt";
  if (std::filesystem::exists(poses) && std::filesystem::exists(calib)) return sim::loadKittiTrajectory(poses, calib);
  return sim::loopRoute();
}

}  // namespace sglc::bench
