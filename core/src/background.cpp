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

namespace {

// Azimuth sector (0 .. sectors - 1, from -pi; +pi is sector 0, as the view context counts) of the point (x, y)
// around the sensor; inv_sector = sectors / 2 pi.
int azimuthSector(double x, double y, double inv_sector, int sectors) {
  return std::clamp(static_cast<int>((std::atan2(y, x) + std::numbers::pi) * inv_sector), 0, sectors) % sectors;
}

}  // namespace

std::vector<float> structureSpectrum(const std::vector<BevCell>& cells, double cell, int rings, int orders,
                                     const DescriptorConfig& config) {
  const int sectors = config.sectors;
  const double rmin = config.ring_min_m, rmax = config.ring_max_m;
  const double half_ring = 0.5 * (rmax - rmin) / rings;
  const double inv_ring = rings / (rmax - rmin), inv_sector = sectors / (2.0 * std::numbers::pi);
  // Occupancy per (part, ring, sector) in [0, 1]. A cell is shared between the two rings whose centres are
  // nearest, in proportion to its distance from each: a wall a few metres nearer on another visit (the other
  // lane, a wider turn) moves weight to the next ring gradually instead of at once.
  std::vector<float> occupied(static_cast<std::size_t>(2) * rings * sectors, 0.0f);
  for (const auto& c : cells) {
    if (c.cls < static_cast<std::uint8_t>(Background::kVegetation) ||
        c.cls > static_cast<std::uint8_t>(Background::kFence))
      continue;
    const double x = (c.ix + 0.5) * cell, y = (c.iy + 0.5) * cell;
    const double rho = std::sqrt(x * x + y * y);
    // Half a ring beyond each edge the outer rings' shares taper to zero instead of stopping at once (a facade
    // standing near ring_min_m would otherwise count fully or not at all).
    if (!(rho >= rmin - half_ring && rho < rmax + half_ring)) continue;
    const double at = (rho - rmin) * inv_ring - 0.5;  // ring coordinate: ring k's centre at k
    const int lo = static_cast<int>(std::floor(at));
    const auto w = static_cast<float>(at - lo);  // share of ring lo + 1
    const int sector = azimuthSector(x, y, inv_sector, sectors);
    const int part = c.cls == static_cast<std::uint8_t>(Background::kVegetation) ? 1 : 0;
    for (const auto& [ring, share] : {std::pair{lo, 1.0f - w}, std::pair{lo + 1, w}}) {
      if (ring < 0 || ring >= rings) continue;  // the innermost and outermost half rings keep their own share only
      float& o = occupied[(static_cast<std::size_t>(part) * rings + ring) * sectors + sector];
      o = std::min(1.0f, o + share);
    }
  }
  // cos and sin of 2 pi k s / sectors, one table for every ring.
  const int K = orders + 1;
  std::vector<double> cs(static_cast<std::size_t>(K) * sectors), sn(cs.size());
  for (int k = 0; k < K; ++k)
    for (int s = 0; s < sectors; ++s) {
      const double a = 2.0 * std::numbers::pi * k * s / sectors;
      cs[static_cast<std::size_t>(k) * sectors + s] = std::cos(a);
      sn[static_cast<std::size_t>(k) * sectors + s] = std::sin(a);
    }
  std::vector<float> out(static_cast<std::size_t>(2) * rings * K, 0.0f);
  for (int r = 0; r < 2 * rings; ++r) {
    const float* occ = &occupied[static_cast<std::size_t>(r) * sectors];
    for (int k = 0; k < K; ++k) {
      double re = 0, im = 0;
      for (int s = 0; s < sectors; ++s)
        if (occ[s] > 0) {
          re += occ[s] * cs[static_cast<std::size_t>(k) * sectors + s];
          im += occ[s] * sn[static_cast<std::size_t>(k) * sectors + s];
        }
      out[static_cast<std::size_t>(r) * K + k] = static_cast<float>(std::hypot(re, im));
    }
  }
  return out;
}

double viewSpanDeg(const std::vector<BevCell>& cells, double cell, double min_range) {
  constexpr int kSectors = 36;
  std::array<bool, kSectors> seen{};
  const double min_sq = min_range * min_range, inv_sector = kSectors / (2.0 * std::numbers::pi);
  for (const auto& c : cells) {
    const double x = (c.ix + 0.5) * cell, y = (c.iy + 0.5) * cell;
    if (x * x + y * y >= min_sq) seen[static_cast<std::size_t>(azimuthSector(x, y, inv_sector, kSectors))] = true;
  }
  return 360.0 * static_cast<double>(std::count(seen.begin(), seen.end(), true)) / kSectors;
}

std::vector<BevCell> bevCells(const Points& points, const std::vector<Background>& point_bg, double cell,
                              double max_range, double max_z) {
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
    if (p.z() > max_z && point_bg[i] != Background::kRoad) continue;  // above the band every sensor sees
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

namespace {

// Sums of one plane voxel's points, relative to its corner (so floats suffice), and its class votes.
struct Acc {
  int n = 0;
  Vec3f corner = Vec3f::Zero();
  std::array<int, 3> cell{0, 0, 0};
  float s[3] = {0, 0, 0};
  float ss[6] = {0, 0, 0, 0, 0, 0};  // xx, xy, xz, yy, yz, zz
  int votes[5] = {0, 0, 0, 0, 0};
  void add(const Vec3f& p, Background b) {
    const float x = p.x() - corner.x(), y = p.y() - corner.y(), z = p.z() - corner.z();
    ++n;
    s[0] += x;
    s[1] += y;
    s[2] += z;
    ss[0] += x * x;
    ss[1] += x * y;
    ss[2] += x * z;
    ss[3] += y * y;
    ss[4] += y * z;
    ss[5] += z * z;
    ++votes[static_cast<int>(b)];
  }
};

}  // namespace

std::vector<Plane> extractPlanes(const Points& points, const std::vector<Background>& point_bg,
                                 const FingerprintConfig& config) {
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
    acc[last].add(p, b);
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
                    const Mat4d& T_q_c, double grid_cell, double radius, StructureClasses classes,
                    const std::vector<bool>* field) {
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
  std::vector<std::uint8_t> wq(q.size()), wc(q.size());
  for (std::size_t i = 0; i < q.size(); ++i) {
    wq[i] = q[i].winner();
    wc[i] = c[i].winner();
  }
  // A view has seen a cell when it holds something (road included) in the cell or next to it. Where one view
  // holds nothing, the other's structure there may be hidden from it or out of its field of view: no evidence.
  auto seen = [g](const std::vector<std::uint8_t>& w, int x, int y) {
    for (int yy = std::max(0, y - 1); yy <= std::min(g - 1, y + 1); ++yy)
      for (int xx = std::max(0, x - 1); xx <= std::min(g - 1, x + 1); ++xx)
        if (w[static_cast<std::size_t>(yy) * g + xx]) return true;
    return false;
  };
  constexpr auto kRoad = static_cast<std::uint8_t>(Background::kRoad);
  std::size_t same = 0, judged = 0;
  for (int y = 0; y < g; ++y)
    for (int x = 0; x < g; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * g + x;
      const std::uint8_t a = wq[i], b = wc[i];
      if (a <= kRoad && b <= kRoad) continue;  // no structure in either: road agrees with any street
      if (!seen(wq, x, y) || !seen(wc, x, y)) continue;
      if (field && !field->empty() &&
          !(*field)[static_cast<std::size_t>(azimuthSector(
              (x + 0.5) * grid_cell - radius, (y + 0.5) * grid_cell - radius,
              static_cast<double>(field->size()) / (2.0 * std::numbers::pi), static_cast<int>(field->size())))])
        continue;
      ++judged;
      same += a == b || (classes == StructureClasses::kMerged && a > kRoad && b > kRoad);
    }
  return judged == 0 ? 0.0 : static_cast<double>(same) / static_cast<double>(judged);
}

}  // namespace sglc
