#include "sglc/plane_index.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

namespace sglc {
namespace {

int cellOf(double x, double inv) { return static_cast<int>(std::floor(x * inv)); }

// Squared distance from x to the interval [a, b].
double gapSquared(double x, double a, double b) {
  const double d = x < a ? a - x : (x > b ? x - b : 0.0);
  return d * d;
}

}  // namespace

PlaneIndex::PlaneIndex(const std::vector<Plane>& planes, double radius) : plane_count_(planes.size()), radius_(radius) {
  if (!(radius > 0) || !std::isfinite(radius))
    throw InputError("plane index: the radius must be positive and finite, not " + std::to_string(radius));
  // Cells of the radius' size: a plane lies within the radius of at most the 3 x 3 x 3 cells around its own.
  const double cell = radius;
  inv_cell_ = 1.0 / cell;
  // Cell coordinates must fit an int with room to spare (packCell wraps them, which only adds candidates).
  constexpr double kMaxCell = 1 << 30;
  for (const auto& plane : planes)
    if (!plane.centroid.allFinite() ||
        !((plane.centroid.cast<double>().cwiseAbs().maxCoeff() + radius) * inv_cell_ + 2 < kMaxCell))
      throw InputError("plane index: a plane centroid is not finite, or too far out for a radius of " +
                       std::to_string(radius) + " m");
  // Cells whose box is within the radius of a centroid, with a margin for rounding: an extra entry costs one
  // distance test, a missing one a wrong answer.
  const double reach_sq = radius * radius * (1.0 + 1e-6) + 1e-9;
  std::vector<std::pair<std::uint64_t, std::int32_t>> entries;
  entries.reserve(planes.size() * 20);
  for (std::size_t i = 0; i < planes.size(); ++i) {
    const Vec3f& c = planes[i].centroid;
    if (i == 0) lo_ = hi_ = c;
    lo_ = lo_.cwiseMin(c);
    hi_ = hi_.cwiseMax(c);
    int from[3], to[3];
    for (int a = 0; a < 3; ++a) {
      from[a] = cellOf(c[a] - radius, inv_cell_);
      to[a] = cellOf(c[a] + radius, inv_cell_);
    }
    for (int x = from[0]; x <= to[0]; ++x)
      for (int y = from[1]; y <= to[1]; ++y)
        for (int z = from[2]; z <= to[2]; ++z) {
          const double gap = gapSquared(c.x(), x * cell, (x + 1) * cell) + gapSquared(c.y(), y * cell, (y + 1) * cell) +
                             gapSquared(c.z(), z * cell, (z + 1) * cell);
          if (gap <= reach_sq) entries.emplace_back(packCell(x, y, z), static_cast<std::int32_t>(i));
        }
  }
  if (!planes.empty()) {
    // Grown a little past the radius: float rounding must never put a point within reach outside.
    const Vec3f grow = Vec3f::Constant(static_cast<float>(radius * (1.0 + 1e-5) + 1e-5));
    lo_ -= grow;
    hi_ += grow;
  }
  std::sort(entries.begin(), entries.end());
  cells_.reset(entries.size() / 8 + 1);
  members_.reserve(entries.size());
  for (std::size_t k = 0; k < entries.size(); ++k) {
    if (k == 0 || entries[k].first != entries[k - 1].first) {
      cells_.findOrInsert(entries[k].first, static_cast<std::int32_t>(starts_.size()));
      starts_.push_back(static_cast<std::uint32_t>(members_.size()));
    }
    members_.push_back(entries[k].second);
  }
  starts_.push_back(static_cast<std::uint32_t>(members_.size()));
}

int PlaneIndex::nearest(const std::vector<Plane>& planes, const Vec3f& p, const Vec3f& n, double max_dist,
                        double min_cos) const {
  if (planes.size() != plane_count_)
    throw InputError("plane index: built for " + std::to_string(plane_count_) + " planes, asked about a set of " +
                     std::to_string(planes.size()));
  if (members_.empty()) return -1;  // no planes (or default-constructed)
  if (!(max_dist >= 0 && max_dist <= radius_))
    throw InputError("plane index: a lookup within " + std::to_string(max_dist) + " m of an index built for " +
                     std::to_string(radius_) + " m");
  // Outside the grown bounds (or not a number): no plane is near, and the cell coordinates could overflow.
  if (!((p.array() >= lo_.array()).all() && (p.array() <= hi_.array()).all())) return -1;
  const int row = cells_.find(packCell(cellOf(p.x(), inv_cell_), cellOf(p.y(), inv_cell_), cellOf(p.z(), inv_cell_)));
  if (row < 0) return -1;
  float best = static_cast<float>(max_dist * max_dist);
  int arg = -1;
  const float mc = static_cast<float>(min_cos);
  for (std::uint32_t k = starts_[row], end = starts_[row + 1]; k < end; ++k) {
    const Plane& plane = planes[static_cast<std::size_t>(members_[k])];
    const float d2 = (plane.centroid - p).squaredNorm();
    if (d2 < best && std::abs(plane.normal.dot(n)) >= mc) {
      best = d2;
      arg = members_[k];
    }
  }
  return arg;
}

}  // namespace sglc
