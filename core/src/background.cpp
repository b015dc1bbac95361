#include "sglc/background.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "fast_math.hpp"
#include "sglc/voxel_map.hpp"

namespace sglc {

std::vector<float> ringKey(const Points& points, const std::vector<Background>& point_bg,
                           const DescriptorConfig& config) {
  const int rings = config.rings, sectors = config.sectors;
  const float rmin = static_cast<float>(config.ring_min_m), rmax = static_cast<float>(config.ring_max_m);
  const float inv_ring = static_cast<float>(rings / (config.ring_max_m - config.ring_min_m));
  const float inv_sector = static_cast<float>(sectors / (2.0 * std::numbers::pi));
  std::vector<std::uint8_t> occupied(static_cast<std::size_t>(2 * rings * sectors), 0);
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Background b = point_bg[i];
    if (b != Background::kBuilding && b != Background::kRoad) continue;
    const Vec3f& p = points[i];
    const float rho = std::sqrt(p.x() * p.x() + p.y() * p.y());
    if (rho < rmin || rho >= rmax) continue;
    const int ring = std::min(static_cast<int>((rho - rmin) * inv_ring), rings - 1);
    const int sector =
        std::min(static_cast<int>((detail::fastAtan2(p.y(), p.x()) + std::numbers::pi_v<float>) * inv_sector),
                 sectors - 1);
    const int part = b == Background::kBuilding ? 0 : 1;
    occupied[(static_cast<std::size_t>(part) * rings + ring) * sectors + sector] = 1;
  }
  std::vector<float> key(2 * rings, 0.0f);
  for (int r = 0; r < 2 * rings; ++r) {
    int count = 0;
    for (int s = 0; s < sectors; ++s) count += occupied[static_cast<std::size_t>(r) * sectors + s];
    key[r] = static_cast<float>(count);
  }
  double norm = 0;
  for (float v : key) norm += double(v) * v;
  if (norm > 0)
    for (float& v : key) v = static_cast<float>(v / std::sqrt(norm));
  return key;
}

std::vector<BevCell> bevCells(const Points& points, const std::vector<Background>& point_bg, double cell,
                              double max_range) {
  const float inv = static_cast<float>(1.0 / cell);
  const float r2 = static_cast<float>(max_range * max_range);
  VoxelMap map(4096);
  std::vector<BevCell> cells;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (point_bg[i] == Background::kNone) continue;
    const Vec3f& p = points[i];
    if (p.x() * p.x() + p.y() * p.y() > r2) continue;
    const int ix = static_cast<int>(std::floor(p.x() * inv)), iy = static_cast<int>(std::floor(p.y() * inv));
    bool inserted = false;
    const int idx = map.findOrInsert(packCell(ix, iy, 0), static_cast<int>(cells.size()), &inserted);
    const auto cls = static_cast<std::uint8_t>(point_bg[i]);
    if (inserted) cells.push_back({static_cast<std::int16_t>(ix), static_cast<std::int16_t>(iy), cls});
    else cells[idx].cls = std::max(cells[idx].cls, cls);
  }
  std::sort(cells.begin(), cells.end(),
            [](const BevCell& a, const BevCell& b) { return a.iy != b.iy ? a.iy < b.iy : a.ix < b.ix; });
  return cells;
}

std::vector<Plane> extractPlanes(const Points& points, const std::vector<Background>& point_bg,
                                 const FingerprintConfig& config) {
  struct Acc {
    int n = 0;
    Vec3d origin = Vec3d::Zero();  // first point: sums are taken relative to it for precision
    Vec3d sum = Vec3d::Zero();
    Mat3d outer = Mat3d::Zero();
    int votes[5] = {0, 0, 0, 0, 0};
  };
  const double inv = 1.0 / config.plane_voxel_m;
  const float r2 = static_cast<float>(config.plane_max_range_m * config.plane_max_range_m);
  VoxelMap map(4096);
  std::vector<Acc> acc;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Background b = point_bg[i];
    if (b != Background::kRoad && b != Background::kBuilding && b != Background::kFence) continue;
    const Vec3f& p = points[i];
    if (p.squaredNorm() > r2) continue;
    const Vec3d q = p.cast<double>();
    bool inserted = false;
    const int idx = map.findOrInsert(packCell(static_cast<int>(std::floor(q.x() * inv)),
                                              static_cast<int>(std::floor(q.y() * inv)),
                                              static_cast<int>(std::floor(q.z() * inv))),
                                     static_cast<int>(acc.size()), &inserted);
    if (inserted) {
      acc.emplace_back();
      acc.back().origin = q;
    }
    Acc& a = acc[idx];
    const Vec3d d = q - a.origin;
    ++a.n;
    a.sum += d;
    a.outer += d * d.transpose();
    ++a.votes[static_cast<int>(b)];
  }
  const double max_var = config.plane_max_thickness_m * config.plane_max_thickness_m;
  std::vector<Plane> planes;
  for (const Acc& a : acc) {
    if (a.n < config.plane_min_points) continue;
    const Vec3d mean = a.sum / a.n;
    const Mat3d cov = a.outer / a.n - mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Mat3d> eig;
    eig.computeDirect(cov);
    if (eig.eigenvalues()[0] > max_var || eig.eigenvalues()[1] < 4.0 * max_var) continue;  // thin and 2-D
    Vec3d normal = eig.eigenvectors().col(0).normalized();
    const Vec3d centroid = a.origin + mean;
    if (normal.dot(centroid) > 0) normal = -normal;  // face the sensor
    Plane plane;
    for (int k = 0; k < 3; ++k) {
      plane.centroid[k] = detail::snapCm(static_cast<float>(centroid[k]));
      plane.normal[k] = static_cast<float>(std::lround(normal[k] * 32767.0)) / 32767.0f;
    }
    int best = static_cast<int>(Background::kRoad);
    for (int c = 1; c < 5; ++c)
      if (a.votes[c] > a.votes[best]) best = c;
    plane.cls = static_cast<std::uint8_t>(best);
    planes.push_back(plane);
  }
  return planes;
}

double bevAgreement(const std::vector<BevCell>& query, const std::vector<BevCell>& candidate, double stored_cell,
                    const Mat4d& T_q_c, double grid_cell, double radius) {
  const int g = static_cast<int>(std::ceil(2.0 * radius / grid_cell));
  const double inv = 1.0 / grid_cell;
  std::vector<std::uint8_t> q(static_cast<std::size_t>(g) * g, 0), c(q.size(), 0);
  auto put = [&](std::vector<std::uint8_t>& grid, double x, double y, std::uint8_t cls) {
    const int gx = static_cast<int>(std::floor((x + radius) * inv)), gy = static_cast<int>(std::floor((y + radius) * inv));
    if (gx < 0 || gy < 0 || gx >= g || gy >= g) return;
    auto& v = grid[static_cast<std::size_t>(gy) * g + gx];
    v = std::max(v, cls);
  };
  for (const auto& cell : query)
    put(q, (cell.ix + 0.5) * stored_cell, (cell.iy + 0.5) * stored_cell, cell.cls);
  const double r00 = T_q_c(0, 0), r01 = T_q_c(0, 1), r10 = T_q_c(1, 0), r11 = T_q_c(1, 1);
  const double tx = T_q_c(0, 3), ty = T_q_c(1, 3);
  for (const auto& cell : candidate) {
    const double x = (cell.ix + 0.5) * stored_cell, y = (cell.iy + 0.5) * stored_cell;
    put(c, r00 * x + r01 * y + tx, r10 * x + r11 * y + ty, cell.cls);
  }
  std::size_t same = 0, either = 0;
  for (std::size_t i = 0; i < q.size(); ++i) {
    if (q[i] == 0 && c[i] == 0) continue;
    ++either;
    if (q[i] == c[i]) ++same;
  }
  return either == 0 ? 0.0 : static_cast<double>(same) / static_cast<double>(either);
}

}  // namespace sglc
