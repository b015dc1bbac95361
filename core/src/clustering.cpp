#include "sglc/clustering.hpp"

#include <array>
#include <cmath>
#include <numbers>

#include "fast_math.hpp"
#include "sglc/voxel_map.hpp"

namespace sglc {
namespace {

int findRoot(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

void unite(std::vector<int>& parent, int a, int b) {
  a = findRoot(parent, a);
  b = findRoot(parent, b);
  if (a == b) return;
  if (a < b)
    parent[b] = a;  // smaller index wins: the result does not depend on visiting order
  else
    parent[a] = b;
}

}  // namespace

std::vector<Cluster> clusterInstances(const Points& points, const std::vector<std::int8_t>& point_class,
                                      const ClusterConfig& config) {
  constexpr float kPi = std::numbers::pi_v<float>;
  const float el_step = static_cast<float>(config.elevation_deg * std::numbers::pi / 180.0);
  const float inv_range = static_cast<float>(1.0 / config.range_m);
  // A whole number of azimuth sectors (the width is adjusted to divide the circle), so that the first and the
  // last sector really are neighbours across the +-pi cut.
  const int n_az = std::max(1, static_cast<int>(std::lround(360.0 / config.azimuth_deg)));
  const float az_scale = static_cast<float>(n_az / (2.0 * std::numbers::pi));
  const float max_range2 = static_cast<float>(config.max_range_m * config.max_range_m);

  struct Voxel {
    int az, r, el, cls;
  };
  std::vector<Voxel> voxels;
  VoxelMap map(1024);
  std::vector<int> point_voxel(points.size(), -1);
  std::uint64_t last_key = ~0ull;
  int last_id = -1;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const int cls = point_class[i];
    if (cls < 0) continue;
    const Vec3f& p = points[i];
    const float rho2 = p.x() * p.x() + p.y() * p.y();
    if (rho2 > max_range2 || rho2 < 1e-6f) continue;
    const float rho = std::sqrt(rho2);
    Voxel v;
    v.az = std::min(static_cast<int>((detail::fastAtan2(p.y(), p.x()) + kPi) * az_scale), n_az - 1);
    v.r = static_cast<int>(rho * inv_range);
    v.el = static_cast<int>((detail::fastAtan2(p.z(), rho) + kPi / 2) / el_step);
    v.cls = cls;
    const std::uint64_t key = packCell(v.az, v.r, v.el + cls * 32768);
    if (key != last_key) {  // consecutive points of a scan line often share a voxel
      bool inserted = false;
      last_id = map.findOrInsert(key, static_cast<int>(voxels.size()), &inserted);
      if (inserted) voxels.push_back(v);
      last_key = key;
    }
    point_voxel[i] = last_id;
  }

  // Union occupied voxels with their 26 neighbours (each pair visited from one side only).
  std::vector<int> parent(voxels.size());
  for (std::size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<int>(i);
  for (std::size_t i = 0; i < voxels.size(); ++i) {
    const Voxel& v = voxels[i];
    for (int da = -1; da <= 1; ++da)
      for (int dr = -1; dr <= 1; ++dr)
        for (int de = -1; de <= 1; ++de) {
          if (std::array{da, dr, de} <= std::array{0, 0, 0}) continue;  // half of the neighbourhood
          const int az = (v.az + da + n_az) % n_az;
          const int j = map.find(packCell(az, v.r + dr, v.el + de + v.cls * 32768));
          if (j >= 0) unite(parent, static_cast<int>(i), j);
        }
  }

  // Number clusters by the first point that reaches them, so the order is stable.
  std::vector<int> root_cluster(voxels.size(), -1);
  std::vector<Cluster> clusters;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (point_voxel[i] < 0) continue;
    const int root = findRoot(parent, point_voxel[i]);
    if (root_cluster[root] < 0) {
      root_cluster[root] = static_cast<int>(clusters.size());
      clusters.push_back({voxels[root].cls, {}});
    }
    clusters[root_cluster[root]].points.push_back(static_cast<std::uint32_t>(i));
  }
  std::vector<Cluster> kept;
  for (auto& c : clusters)
    if (static_cast<int>(c.points.size()) >= config.min_points) kept.push_back(std::move(c));
  std::stable_sort(kept.begin(), kept.end(), [](const Cluster& a, const Cluster& b) { return a.cls < b.cls; });
  return kept;
}

}  // namespace sglc
