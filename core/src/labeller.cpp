#include "sglc/labeller.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

#include "fast_math.hpp"
#include "sglc/voxel_map.hpp"

namespace sglc {
namespace {

namespace id = labeller_ids;
constexpr float kInf = std::numeric_limits<float>::infinity();

// Ground: per column of ground_cell_m, a floor and a plane z = a x + b y + c through the column's points just
// above it. Two floors: the column's own (its second-lowest point, robust to one stray return below the road)
// and its 3 x 3 neighbourhood's (a column under a car sees the road beside it). The own floor's plane stands
// unless it is more than ground_max_step_m above the own planes of two neighbours where the columns meet: so
// slopes stay ground, and a raised column (a car, a bush, a wall's foot) takes the neighbourhood's floor.
class Ground {
 public:
  Ground(const Points& points, const LabellerConfig& c) : cell_(static_cast<float>(c.ground_cell_m)) {
    half_ = static_cast<int>(std::ceil(c.max_range_m / c.ground_cell_m)) + 1;
    side_ = 2 * half_ + 1;
    const std::size_t n_cells = static_cast<std::size_t>(side_) * static_cast<std::size_t>(side_);
    setUpColumns(n_cells);
    std::vector<float> low1(n_cells, kInf), low2(n_cells, kInf);  // two lowest points per column
    const float r2 = static_cast<float>(c.max_range_m * c.max_range_m);
    column_.assign(points.size(), -1);
    for (std::size_t i = 0; i < points.size(); ++i) {
      const auto& p = points[i];
      if (!p.allFinite() || p.x() * p.x() + p.y() * p.y() > r2) continue;
      const int k = index(p);
      column_[i] = k;
      // The two lowest, without a branch (heights come in no order a branch predictor could learn).
      const float l1 = low1[k];
      low1[k] = std::min(p.z(), l1);
      low2[k] = std::min(low2[k], std::max(p.z(), l1));
    }
    std::vector<float> own(n_cells, kInf), near(n_cells, kInf);
    for (std::size_t k = 0; k < n_cells; ++k) own[k] = std::isfinite(low2[k]) ? low2[k] : low1[k];
    for (int y = 0; y < side_; ++y)
      for (int x = 0; x < side_; ++x) {
        float f = kInf;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx >= 0 && yy >= 0 && xx < side_ && yy < side_) f = std::min(f, own[cellAt(xx, yy)]);
          }
        near[cellAt(x, y)] = f;
      }
    // Sums of the column's points within ground_band_m of each floor, relative to the column's corner and its
    // floor: small numbers, so float sums keep their precision.
    std::vector<PlaneSums> own_sums(n_cells), near_sums(n_cells);
    const float band = static_cast<float>(c.ground_band_m);
    for (std::size_t i = 0; i < points.size(); ++i) {
      const int k = column_[i];
      if (k < 0) continue;
      const auto& p = points[i];
      const float x = p.x() - cornerX(k), y = p.y() - cornerY(k);
      if (p.z() <= own[k] + band) own_sums[k].add(x, y, p.z() - own[k]);
      if (p.z() <= near[k] + band) near_sums[k].add(x, y, p.z() - near[k]);
    }
    std::vector<Eigen::Vector3f> own_plane(n_cells);
    for (std::size_t k = 0; k < n_cells; ++k) own_plane[k] = plane(own_sums[k], own[k], static_cast<int>(k));
    const float step = static_cast<float>(c.ground_max_step_m);
    plane_.assign(n_cells, Eigen::Vector3f(0, 0, kInf));
    for (int y = 0; y < side_; ++y)
      for (int x = 0; x < side_; ++x) {
        const int k = cellAt(x, y);
        const auto ku = static_cast<std::size_t>(k);
        if (!std::isfinite(own[ku])) continue;  // no points: never asked
        // Compared where the two columns meet (half a column from each centre), so a tilt is extrapolated
        // over little distance.
        const float cx = cornerX(k) + 0.5f * cell_, cy = cornerY(k) + 0.5f * cell_;
        auto at = [](const Eigen::Vector3f& g, float px, float py) { return g.x() * px + g.y() * py + g.z(); };
        int below = 0;  // neighbours whose ground lies more than a step lower
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if ((dx == 0 && dy == 0) || xx < 0 || yy < 0 || xx >= side_ || yy >= side_) continue;
            const auto n = static_cast<std::size_t>(cellAt(xx, yy));
            // Only planes fitted to enough points: a level fallback is no reference on a slope.
            if (own_sums[n].n < 6) continue;
            const float mx = cx + 0.5f * cell_ * static_cast<float>(dx),
                        my = cy + 0.5f * cell_ * static_cast<float>(dy);
            below += !(at(own_plane[ku], mx, my) <= at(own_plane[n], mx, my) + step);
          }
        // Two neighbours, so that one badly fitted neighbour (a sliver of points) does not lift a slope.
        plane_[ku] = below >= 2 ? plane(near_sums[ku], near[ku], k) : own_plane[ku];
      }
  }

  // Height of point i above the ground of its column (+inf where it has none: out of range, non-finite).
  float height(std::size_t i, const Vec3f& p) const {
    const int k = column_[i];
    if (k < 0) return kInf;
    const auto& g = plane_[static_cast<std::size_t>(k)];
    if (!std::isfinite(g.z())) return kInf;
    return p.z() - (g.x() * p.x() + g.y() * p.y() + g.z());
  }

 private:
  // Column corners per column (a division and a remainder per point otherwise). A power-of-two cell divides
  // exactly by multiplying with its inverse; any other is divided as it was.
  void setUpColumns(std::size_t n_cells) {
    corner_x_.resize(n_cells);
    corner_y_.resize(n_cells);
    for (std::size_t k = 0; k < n_cells; ++k) {
      corner_x_[k] = static_cast<float>(static_cast<int>(k) % side_ - half_) * cell_;
      corner_y_[k] = static_cast<float>(static_cast<int>(k) / side_ - half_) * cell_;
    }
    int exponent = 0;
    exact_inverse_ = std::frexp(cell_, &exponent) == 0.5f;
    inv_cell_ = 1.0f / cell_;
  }

  int index(const Vec3f& p) const {
    const float fx = exact_inverse_ ? p.x() * inv_cell_ : p.x() / cell_;
    const float fy = exact_inverse_ ? p.y() * inv_cell_ : p.y() / cell_;
    const int x = std::clamp(detail::floorInt(fx) + half_, 0, side_ - 1);
    const int y = std::clamp(detail::floorInt(fy) + half_, 0, side_ - 1);
    return cellAt(x, y);
  }
  int cellAt(int x, int y) const { return y * side_ + x; }

  struct PlaneSums {
    float n = 0, x = 0, y = 0, z = 0, xx = 0, xy = 0, yy = 0, xz = 0, yz = 0;
    void add(float px, float py, float pz) {
      n += 1;
      x += px, y += py, z += pz;
      xx += px * px, xy += px * py, yy += py * py, xz += px * pz, yz += py * pz;
    }
  };
  // Plane z = a x + b y + c (scan coordinates) of column k from its sums relative to its corner and `floor`:
  // tilted when the fit is well conditioned and no steeper than 30 %, else level at the points' mean height;
  // the floor itself without points; +inf c without a floor.
  Eigen::Vector3f plane(const PlaneSums& s, float floor, int k) const {
    if (!std::isfinite(floor)) return {0, 0, kInf};
    if (s.n < 1) return {0, 0, floor};
    Eigen::Vector3d sol(0, 0, s.z / s.n);
    if (s.n >= 6) {
      Eigen::Matrix3d A;
      A << s.xx, s.xy, s.x, s.xy, s.yy, s.y, s.x, s.y, s.n;
      const Eigen::Vector3d b(s.xz, s.yz, s.z);
      const Eigen::Vector3d fit = A.ldlt().solve(b);
      const double spread = (s.xx - s.x * s.x / s.n) + (s.yy - s.y * s.y / s.n);
      if (fit.allFinite() && std::hypot(fit.x(), fit.y()) < 0.3 && spread / s.n > 0.1) sol = fit;
    }
    // Back to scan coordinates: z = a (x - x0) + b (y - y0) + c + floor.
    sol.z() += floor - sol.x() * cornerX(k) - sol.y() * cornerY(k);
    return sol.cast<float>();
  }

  float cornerX(int k) const { return corner_x_[static_cast<std::size_t>(k)]; }
  float cornerY(int k) const { return corner_y_[static_cast<std::size_t>(k)]; }

  float cell_;
  float inv_cell_ = 1.0f;
  bool exact_inverse_ = false;
  std::vector<float> corner_x_, corner_y_;
  int half_ = 0, side_ = 0;
  std::vector<int> column_;             // per point: its column, or -1 (out of range, non-finite)
  std::vector<Eigen::Vector3f> plane_;  // a, b, c of z = a x + b y + c
};

struct Column {
  int low = 0, high = 0;  // points in the object band / above it
  float high_max = 0;     // highest point above the ground
  int component = -1;     // object (union-find root after the pass)
};

int findRoot(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

struct Object {
  double n = 0, x = 0, y = 0, xx = 0, xy = 0, yy = 0;
  float h_min = kInf, h_max = -kInf;  // of its band points
  float top = 0;                      // highest point of its columns (band and above)
  int columns = 0;
  std::uint32_t label = id::kVegetation;
};

// Points above the band around a place, and the columns holding them (canopy test for pole-like objects).
std::pair<int, int> highAround(const VoxelMap& map, const std::vector<Column>& cols, float inv_cell, double x, double y,
                               double radius) {
  const int r = static_cast<int>(std::ceil(radius * inv_cell));
  const int cx = detail::floorInt(static_cast<float>(x) * inv_cell),
            cy = detail::floorInt(static_cast<float>(y) * inv_cell);
  int count = 0, cells = 0;
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      const int j = map.find(packCell(cx + dx, cy + dy, 0));
      if (j >= 0 && cols[static_cast<std::size_t>(j)].high > 0) {
        count += cols[static_cast<std::size_t>(j)].high;
        ++cells;
      }
    }
  return std::make_pair(count, cells);
}

// Each object's label from its footprint (extents of its band points) and height; vegetation when none fits.
void classifyObjects(std::vector<Object>& objects, const VoxelMap& map, const std::vector<Column>& cols, float inv_cell,
                     const LabellerConfig& c) {
  for (auto& o : objects) {
    if (o.n < 3) continue;  // a stray point or two: vegetation
    const double mx = o.x / o.n, my = o.y / o.n;
    Eigen::Matrix2d cov;
    cov << o.xx / o.n - mx * mx, o.xy / o.n - mx * my, o.xy / o.n - mx * my, o.yy / o.n - my * my;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    // Extents of a uniform spread: sqrt(12) standard deviations; a column alone is one cell wide.
    const double length = std::max(std::sqrt(12.0 * std::max(eig.eigenvalues()[1], 0.0)), c.cell_m);
    const double width = std::max(std::sqrt(12.0 * std::max(eig.eigenvalues()[0], 0.0)), c.cell_m);
    const double height = std::max<double>(o.h_max, o.top);
    const bool grounded = o.h_min <= 0.7f;
    if (length <= c.pole_max_width_m && height >= c.pole_min_height_m && grounded) {
      // A trunk carries a canopy: many points above the band spread around it, beyond its own columns.
      const auto [high, cells] = highAround(map, cols, inv_cell, mx, my, 2.0);
      o.label = cells >= 12 && high >= 40 ? id::kTrunk : id::kPole;
    } else if (length >= c.wall_min_length_m && width <= c.wall_max_width_m) {
      o.label = height >= c.wall_min_height_m ? id::kBuilding : id::kFence;
    } else if (length >= c.vehicle_min_length_m && length <= c.vehicle_max_length_m && width <= c.vehicle_max_width_m &&
               o.h_max >= c.vehicle_min_height_m && o.top <= c.vehicle_max_height_m && grounded) {
      o.label = id::kVehicle;
    } else if (length >= 2 * c.wall_min_length_m && height >= c.wall_min_height_m) {
      o.label = id::kBuilding;  // large and tall: a building's corner or front
    }
  }
}

// Objects: columns with band points linked within link_m (at least the 8 neighbours: sparse or downsampled clouds
// leave gaps between the columns of one wall), with their columns and top; object_of[k] is column k's object (-1
// for a column without band points).
std::vector<Object> groupObjects(const std::vector<Column>& cols, const std::vector<std::pair<int, int>>& col_xy,
                                 const VoxelMap& map, const LabellerConfig& c, std::vector<int>& object_of) {
  const int reach = std::max(1, static_cast<int>(std::lround(c.link_m / c.cell_m)));
  std::vector<int> parent(cols.size());
  for (std::size_t k = 0; k < cols.size(); ++k) parent[k] = static_cast<int>(k);
  for (std::size_t k = 0; k < cols.size(); ++k) {
    if (!cols[k].low) continue;
    const auto [cx, cy] = col_xy[k];
    for (int dy = 0; dy <= reach; ++dy)
      for (int dx = -reach; dx <= reach; ++dx) {
        if (dy == 0 && dx <= 0) continue;  // each neighbour pair once
        const int j = map.find(packCell(cx + dx, cy + dy, 0));
        if (j < 0 || !cols[static_cast<std::size_t>(j)].low) continue;
        const int a = findRoot(parent, static_cast<int>(k)), b = findRoot(parent, j);
        if (a != b) parent[static_cast<std::size_t>(std::max(a, b))] = std::min(a, b);
      }
  }
  object_of.assign(cols.size(), -1);
  std::vector<Object> objects;
  for (std::size_t k = 0; k < cols.size(); ++k) {
    if (!cols[k].low) continue;
    const int root = findRoot(parent, static_cast<int>(k));
    if (object_of[static_cast<std::size_t>(root)] < 0) {
      object_of[static_cast<std::size_t>(root)] = static_cast<int>(objects.size());
      objects.emplace_back();
    }
    object_of[k] = object_of[static_cast<std::size_t>(root)];
    auto& o = objects[static_cast<std::size_t>(object_of[k])];
    ++o.columns;
    o.top = std::max(o.top, cols[k].high_max);
  }
  return objects;
}

// A point above the band over an object labelled `object`: the object's label where it continues upwards (walls,
// poles; vehicles up to their height; a fence's upper part is a building), else vegetation.
std::uint32_t aboveBandLabel(std::uint32_t object, float height, const LabellerConfig& c) {
  if (object == id::kBuilding || object == id::kPole) return object;
  if (object == id::kFence) return id::kBuilding;
  if (object == id::kVehicle && height <= c.vehicle_max_height_m) return id::kVehicle;
  return id::kVegetation;
}

}  // namespace

std::vector<std::uint32_t> labelScene(const Points& points, const LabellerConfig& c) {
  const std::size_t n = points.size();
  std::vector<std::uint32_t> out(n, id::kNone);
  if (n == 0) return out;
  const Ground ground(points, c);
  const float tol = static_cast<float>(c.ground_tolerance_m), band = static_cast<float>(c.low_band_m);
  const float inv_cell = static_cast<float>(1.0 / c.cell_m);

  // Heights, ground, and object columns.
  std::vector<float> h(n, kInf);
  std::vector<int> col_of(n, -1);
  VoxelMap map(n / 4 + 64);
  std::vector<Column> cols;
  std::vector<std::pair<int, int>> col_xy;
  int last_x = std::numeric_limits<int>::min(), last_y = 0, last_k = -1;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f& p = points[i];
    h[i] = ground.height(i, p);
    if (!std::isfinite(h[i]) || h[i] < -0.5f) continue;  // no ground estimate, or far below it: ignored
    if (h[i] <= tol) {
      out[i] = id::kGround;
      continue;
    }
    const int cx = detail::floorInt(p.x() * inv_cell), cy = detail::floorInt(p.y() * inv_cell);
    if (cx != last_x || cy != last_y) {  // neighbouring returns mostly share a column: look up only on a change
      bool inserted = false;
      last_k = map.findOrInsert(packCell(cx, cy, 0), static_cast<int>(cols.size()), &inserted);
      if (inserted) {
        cols.push_back({});
        col_xy.emplace_back(cx, cy);
      }
      last_x = cx, last_y = cy;
    }
    const int k = last_k;
    col_of[i] = k;
    auto& col = cols[static_cast<std::size_t>(k)];
    if (h[i] <= band)
      ++col.low;
    else
      ++col.high;
    col.high_max = std::max(col.high_max, h[i]);
  }

  std::vector<int> object_of;
  std::vector<Object> objects = groupObjects(cols, col_xy, map, c, object_of);
  for (std::size_t i = 0; i < n; ++i) {
    if (col_of[i] < 0 || h[i] > band) continue;
    auto& o = objects[static_cast<std::size_t>(object_of[static_cast<std::size_t>(col_of[i])])];
    const double x = points[i].x(), y = points[i].y();
    o.n += 1;
    o.x += x, o.y += y, o.xx += x * x, o.xy += x * y, o.yy += y * y;
    o.h_min = std::min(o.h_min, h[i]);
    o.h_max = std::max(o.h_max, h[i]);
  }

  classifyObjects(objects, map, cols, inv_cell, c);

  // Labels: band points take their object's; points above it their column's object where that continues
  // upwards (walls, poles; vehicles up to their height), else vegetation.
  for (std::size_t i = 0; i < n; ++i) {
    if (col_of[i] < 0) continue;
    const auto k = static_cast<std::size_t>(col_of[i]);
    const int obj = object_of[k];
    if (h[i] <= band) {
      out[i] = objects[static_cast<std::size_t>(obj)].label;
      continue;
    }
    out[i] = aboveBandLabel(obj >= 0 ? objects[static_cast<std::size_t>(obj)].label : id::kVegetation, h[i], c);
  }
  return out;
}

}  // namespace sglc
