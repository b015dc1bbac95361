#include "sim/ground_truth.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <unordered_map>

#include "sim/rng.hpp"

namespace sglc::sim {
namespace {

void checkInputs(const std::vector<Mat4d>& poses, const std::vector<int>& source) {
  if (poses.size() != source.size())
    throw InputError("ground truth: " + std::to_string(poses.size()) + " poses but " + std::to_string(source.size()) +
                     " frame indices");
  for (std::size_t k = 1; k < source.size(); ++k)
    if (source[k] <= source[k - 1]) throw InputError("ground truth: frame indices must be ascending");
}

double dist2d(const Mat4d& a, const Mat4d& b) { return std::hypot(a(0, 3) - b(0, 3), a(1, 3) - b(1, 3)); }

// For every k, the earlier frames j < k within `radius` (horizontal), via a uniform grid.
template <class Fn>
void forNearPairs(const std::vector<Mat4d>& poses, double radius, Fn&& fn) {
  std::unordered_map<std::int64_t, std::vector<int>> grid;
  auto key = [](std::int64_t x, std::int64_t y) { return (x << 32) ^ (y & 0xFFFFFFFFLL); };
  for (int k = 0; k < static_cast<int>(poses.size()); ++k) {
    const auto cx = static_cast<std::int64_t>(std::floor(poses[k](0, 3) / radius));
    const auto cy = static_cast<std::int64_t>(std::floor(poses[k](1, 3) / radius));
    for (std::int64_t dy = -1; dy <= 1; ++dy)
      for (std::int64_t dx = -1; dx <= 1; ++dx) {
        auto it = grid.find(key(cx + dx, cy + dy));
        if (it == grid.end()) continue;
        for (int j : it->second) fn(k, j);
      }
    grid[key(cx, cy)].push_back(k);
  }
}

}  // namespace

std::vector<LabelledPair> distancePairs(const std::vector<Mat4d>& poses, const std::vector<int>& source,
                                        const PairListConfig& config) {
  checkInputs(poses, source);
  std::vector<LabelledPair> pairs;
  forNearPairs(poses, std::max(config.positive_m, 1e-3), [&](int k, int j) {
    if (source[k] - source[j] > config.min_gap && dist2d(poses[k], poses[j]) < config.positive_m)
      pairs.push_back({k, j, true});
  });
  const std::size_t positives = pairs.size();
  const std::size_t n = poses.size();
  const std::size_t wanted = std::max<std::size_t>(positives * std::max(0, config.negatives_per_positive),
                                                   static_cast<std::size_t>(std::max(0, config.min_negatives)));
  std::set<std::pair<int, int>> negatives;
  if (n >= 2) {
    Rng rng(hashKeys(config.seed, 0x4E6ULL));
    const std::size_t attempts = wanted * 50 + 1000;
    for (std::size_t a = 0; a < attempts && negatives.size() < wanted; ++a) {
      int i = rng.below(static_cast<int>(n)), j = rng.below(static_cast<int>(n));
      if (i == j) continue;
      if (i < j) std::swap(i, j);
      if (dist2d(poses[i], poses[j]) > config.negative_m) negatives.insert({i, j});
    }
  }
  for (const auto& [i, j] : negatives) pairs.push_back({i, j, false});
  std::sort(pairs.begin(), pairs.end(), [](const LabelledPair& a, const LabelledPair& b) {
    return a.query != b.query ? a.query < b.query : a.database < b.database;
  });
  return pairs;
}

std::vector<LoopPose> loopPoses(const std::vector<Mat4d>& poses, const std::vector<int>& source, double max_distance,
                                int min_gap) {
  checkInputs(poses, source);
  std::vector<LoopPose> rows;
  forNearPairs(poses, std::max(max_distance, 1e-3), [&](int k, int j) {
    if (source[k] - source[j] <= min_gap) return;
    if ((poses[k].topRightCorner<3, 1>() - poses[j].topRightCorner<3, 1>()).norm() >= max_distance) return;
    rows.push_back({j, k, poses[k].inverse() * poses[j]});
  });
  std::sort(rows.begin(), rows.end(), [](const LoopPose& a, const LoopPose& b) {
    return a.second != b.second ? a.second < b.second : a.first < b.first;
  });
  return rows;
}

std::vector<Mat4d> driftingOdometry(const std::vector<Mat4d>& poses, const std::vector<int>& source,
                                    const OdometryNoise& noise, std::uint64_t seed) {
  checkInputs(poses, source);
  std::vector<Mat4d> odo;
  if (poses.empty()) return odo;
  odo.push_back(poses[0]);
  for (std::size_t k = 1; k < poses.size(); ++k) {
    const Mat4d step = poses[k - 1].inverse() * poses[k];
    const double len = step.topRightCorner<3, 1>().norm();
    Rng rng(hashKeys(seed, 0x0D0ULL, static_cast<std::uint64_t>(source[k])));
    const double st = noise.translation * len;
    const double sr = noise.rotation_deg_per_m * len * std::numbers::pi / 180.0;
    Mat4d E = Mat4d::Identity();
    const double tx = st * rng.normal(), ty = st * rng.normal(), tz = st * rng.normal();
    const double yaw = sr * rng.normal(), pitch = 0.2 * sr * rng.normal(), roll = 0.2 * sr * rng.normal();
    E.topLeftCorner<3, 3>() = (Eigen::AngleAxisd(yaw, Vec3d::UnitZ()) * Eigen::AngleAxisd(pitch, Vec3d::UnitY()) *
                               Eigen::AngleAxisd(roll, Vec3d::UnitX()))
                                  .toRotationMatrix();
    E.topRightCorner<3, 1>() = Vec3d(tx, ty, tz);
    odo.push_back(odo.back() * step * E);
  }
  return odo;
}

double headingDifferenceDeg(const Mat4d& a, const Mat4d& b) {
  const double ya = std::atan2(a(1, 0), a(0, 0)), yb = std::atan2(b(1, 0), b(0, 0));
  double d = std::abs(ya - yb) * 180.0 / std::numbers::pi;
  d = std::fmod(d, 360.0);
  return d > 180.0 ? 360.0 - d : d;
}

}  // namespace sglc::sim
