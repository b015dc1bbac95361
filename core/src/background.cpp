#include "sglc/background.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <tuple>

#include "class_votes.hpp"
#include "fast_math.hpp"
#include "sglc/voxel_map.hpp"

namespace sglc {

using detail::ClassVotes;

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
    const int sector = std::min(
        static_cast<int>((detail::fastAtan2(p.y(), p.x()) + std::numbers::pi_v<float>)*inv_sector), sectors - 1);
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
  // A dense grid over the disc: cheaper than hashing ~100k points, and the scan comes out sorted.
  const float inv = static_cast<float>(1.0 / cell);
  const float r2 = static_cast<float>(max_range * max_range);
  const int half = static_cast<int>(std::ceil(max_range / cell)) + 1;
  const int side = 2 * half;
  std::vector<ClassVotes> grid(static_cast<std::size_t>(side) * side);
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (point_bg[i] == Background::kNone) continue;
    const Vec3f& p = points[i];
    if (p.x() * p.x() + p.y() * p.y() > r2) continue;
    const int ix = detail::floorInt(p.x() * inv) + half, iy = detail::floorInt(p.y() * inv) + half;
    grid[static_cast<std::size_t>(iy) * side + ix].add(point_bg[i]);
  }
  std::vector<BevCell> cells;
  for (int iy = 0; iy < side; ++iy)
    for (int ix = 0; ix < side; ++ix) {
      const auto v = grid[static_cast<std::size_t>(iy) * side + ix].winner();
      if (v) cells.push_back({static_cast<std::int16_t>(ix - half), static_cast<std::int16_t>(iy - half), v});
    }
  return cells;
}

std::vector<Plane> extractPlanes(const Points& points, const std::vector<Background>& point_bg,
                                 const FingerprintConfig& config) {
  struct Acc {
    int n = 0;
    Vec3f corner = Vec3f::Zero();  // sums are taken relative to the voxel corner, so floats suffice
    std::array<int, 3> cell{0, 0, 0};
    float s[3] = {0, 0, 0};
    float ss[6] = {0, 0, 0, 0, 0, 0};  // xx, xy, xz, yy, yz, zz
    int votes[5] = {0, 0, 0, 0, 0};
  };
  const float voxel = static_cast<float>(config.plane_voxel_m);
  const float inv = 1.0f / voxel;
  const float r2 = static_cast<float>(config.plane_max_range_m * config.plane_max_range_m);
  VoxelMap map(4096);
  std::vector<Acc> acc;
  std::uint64_t last_key = ~0ull;
  int last = -1;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Background b = point_bg[i];
    if (b != Background::kRoad && b != Background::kBuilding && b != Background::kFence) continue;
    const Vec3f& p = points[i];
    if (p.squaredNorm() > r2) continue;
    const int cx = detail::floorInt(p.x() * inv), cy = detail::floorInt(p.y() * inv),
              cz = detail::floorInt(p.z() * inv);
    const std::uint64_t key = packCell(cx, cy, cz);
    if (key != last_key) {  // consecutive points of a scan line often share a voxel
      bool inserted = false;
      last = map.findOrInsert(key, static_cast<int>(acc.size()), &inserted);
      if (inserted) {
        acc.emplace_back();
        acc.back().corner = Vec3f(cx * voxel, cy * voxel, cz * voxel);
        acc.back().cell = {cx, cy, cz};
      }
      last_key = key;
    }
    Acc& a = acc[last];
    const float x = p.x() - a.corner.x(), y = p.y() - a.corner.y(), z = p.z() - a.corner.z();
    ++a.n;
    a.s[0] += x;
    a.s[1] += y;
    a.s[2] += z;
    a.ss[0] += x * x;
    a.ss[1] += x * y;
    a.ss[2] += x * z;
    a.ss[3] += y * y;
    a.ss[4] += y * z;
    a.ss[5] += z * z;
    ++a.votes[static_cast<int>(b)];
  }
  const double max_var = config.plane_max_thickness_m * config.plane_max_thickness_m;
  // Emit in voxel order (z, y, x), so the result does not depend on the order of the points.
  std::vector<std::size_t> order(acc.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) {
    const auto& a = acc[x].cell;
    const auto& b = acc[y].cell;
    return std::tie(a[2], a[1], a[0]) < std::tie(b[2], b[1], b[0]);
  });
  std::vector<Plane> planes;
  for (std::size_t idx : order) {
    const Acc& a = acc[idx];
    if (a.n < config.plane_min_points) continue;
    const Vec3d mean = Vec3d(a.s[0], a.s[1], a.s[2]) / a.n;
    Mat3d cov;
    cov << a.ss[0], a.ss[1], a.ss[2], a.ss[1], a.ss[3], a.ss[4], a.ss[2], a.ss[4], a.ss[5];
    cov = cov / a.n - mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Mat3d> eig;
    eig.computeDirect(cov);
    if (eig.eigenvalues()[0] > max_var || eig.eigenvalues()[1] < 4.0 * max_var) continue;  // thin and 2-D
    Vec3d normal = eig.eigenvectors().col(0).normalized();
    const Vec3d centroid = a.corner.cast<double>() + mean;
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
  std::vector<ClassVotes> q(static_cast<std::size_t>(g) * g), c(q.size());
  auto put = [&](std::vector<ClassVotes>& grid, double x, double y, std::uint8_t cls) {
    const int gx = detail::floorInt((x + radius) * inv), gy = detail::floorInt((y + radius) * inv);
    if (gx < 0 || gy < 0 || gx >= g || gy >= g || cls == 0 || cls > 4) return;
    grid[static_cast<std::size_t>(gy) * g + gx].add(static_cast<Background>(cls));
  };
  for (const auto& cell : query) put(q, (cell.ix + 0.5) * stored_cell, (cell.iy + 0.5) * stored_cell, cell.cls);
  const double r00 = T_q_c(0, 0), r01 = T_q_c(0, 1), r10 = T_q_c(1, 0), r11 = T_q_c(1, 1);
  const double tx = T_q_c(0, 3), ty = T_q_c(1, 3);
  for (const auto& cell : candidate) {
    const double x = (cell.ix + 0.5) * stored_cell, y = (cell.iy + 0.5) * stored_cell;
    put(c, r00 * x + r01 * y + tx, r10 * x + r11 * y + ty, cell.cls);
  }
  std::size_t same = 0, either = 0;
  for (std::size_t i = 0; i < q.size(); ++i) {
    const std::uint8_t a = q[i].winner(), b = c[i].winner();
    if (a == 0 && b == 0) continue;
    ++either;
    if (a == b) ++same;
  }
  return either == 0 ? 0.0 : static_cast<double>(same) / static_cast<double>(either);
}

}  // namespace sglc
