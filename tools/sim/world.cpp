#include "sim/world.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <numbers>
#include <string>

#include "sim/aliasing.hpp"
#include "sim/occupancy.hpp"
#include "sim/rng.hpp"

namespace sglc::sim {
namespace {

using Vec2 = Eigen::Vector2d;

constexpr double kFar = 24.0;            // the distance raster is clamped here (m)
constexpr double kDistCell = 1.0;        // distance and occupancy rasters (m)
constexpr double kHeightCell = 4.0;      // ground height raster (m)
constexpr double kMargin = 160.0;        // rasters cover the path's bounding box grown by this (m)
constexpr double kIndexCell = 32.0;      // static primitive index (m)
constexpr double kDistrictCell = 110.0;  // district size (m)
constexpr double kSegmentCell = 16.0;    // path segment index (m)

// Stream ids, so that every generation pass draws from its own random stream.
enum Stream : std::uint64_t {
  kStyle = 1,
  kDistrictStream,
  kLots,
  kBuildings,
  kFences,
  kKerb,
  kYards,
  kParked,
  kMoving,
  kPeople,
  kTemporary
};

Vec2 leftNormal(const Vec2& t) { return {-t.y(), t.x()}; }

double segmentDistance(const Vec2& p, const Vec2& a, const Vec2& b, double* along = nullptr) {
  const Vec2 ab = b - a;
  const double len2 = ab.squaredNorm();
  double u = len2 > 0 ? (p - a).dot(ab) / len2 : 0.0;
  u = std::clamp(u, 0.0, 1.0);
  if (along) *along = u;
  return (p - (a + u * ab)).norm();
}

// A raster over a large area whose cells are stored in 64 x 64 tiles, allocated on first write.
template <class T>
class TiledGrid {
 public:
  static constexpr int kTile = 64;
  TiledGrid() = default;
  TiledGrid(double x0, double y0, double cell, int nx, int ny, T fill)
      : x0_(x0),
        y0_(y0),
        cell_(cell),
        inv_(1.0 / cell),
        nx_(nx),
        ny_(ny),
        fill_(fill),
        tx_((nx + kTile - 1) / kTile),
        ty_((ny + kTile - 1) / kTile),
        index_(static_cast<std::size_t>(tx_) * ty_, -1) {}

  bool inside(int ix, int iy) const { return ix >= 0 && iy >= 0 && ix < nx_ && iy < ny_; }
  T get(int ix, int iy) const {
    if (!inside(ix, iy)) return fill_;
    const int t = index_[static_cast<std::size_t>(iy / kTile) * tx_ + ix / kTile];
    if (t < 0) return fill_;
    return tiles_[t][(iy % kTile) * kTile + ix % kTile];
  }
  // Requires inside(ix, iy).
  T& at(int ix, int iy) {
    int& t = index_[static_cast<std::size_t>(iy / kTile) * tx_ + ix / kTile];
    if (t < 0) {
      t = static_cast<int>(tiles_.size());
      tiles_.emplace_back(kTile * kTile, fill_);
    }
    return tiles_[t][(iy % kTile) * kTile + ix % kTile];
  }
  int cellX(double x) const { return static_cast<int>(std::floor((x - x0_) * inv_)); }
  int cellY(double y) const { return static_cast<int>(std::floor((y - y0_) * inv_)); }
  double centreX(int ix) const { return x0_ + (ix + 0.5) * cell_; }
  double centreY(int iy) const { return y0_ + (iy + 0.5) * cell_; }
  double cell() const { return cell_; }
  int nx() const { return nx_; }
  int ny() const { return ny_; }
  // Bilinear interpolation between cell centres.
  double bilinear(double x, double y) const {
    const double fx = (x - x0_) * inv_ - 0.5, fy = (y - y0_) * inv_ - 0.5;
    const double flx = std::floor(fx), fly = std::floor(fy);
    const int ix = static_cast<int>(flx), iy = static_cast<int>(fly);
    const double ax = fx - flx, ay = fy - fly;
    const double v00 = get(ix, iy), v10 = get(ix + 1, iy), v01 = get(ix, iy + 1), v11 = get(ix + 1, iy + 1);
    return (1 - ay) * ((1 - ax) * v00 + ax * v10) + ay * ((1 - ax) * v01 + ax * v11);
  }
  std::size_t memoryBytes() const {
    return index_.size() * sizeof(int) + tiles_.size() * (kTile * kTile * sizeof(T) + sizeof(std::vector<T>));
  }

 private:
  double x0_ = 0, y0_ = 0, cell_ = 1, inv_ = 1;
  int nx_ = 0, ny_ = 0;
  T fill_{};
  int tx_ = 0, ty_ = 0;
  std::vector<int> index_;
  std::vector<std::vector<T>> tiles_;
};

struct PathVertex {
  double x, y, z, s;  // z: smoothed ground height under the path
};

// The driven path as a 2-D polyline with arc length, a smoothed ground height, and a segment index for
// exact nearest-point queries.
class Path {
 public:
  void build(const std::vector<Mat4d>& poses, double sensor_height, double extension) {
    std::vector<PathVertex> raw;
    for (const auto& P : poses) {
      const Vec3d p = P.topRightCorner<3, 1>();
      if (raw.empty() || std::hypot(p.x() - raw.back().x, p.y() - raw.back().y) >= 0.5)
        raw.push_back({p.x(), p.y(), p.z() - sensor_height, 0.0});
    }
    if (raw.empty()) throw InputError("world: the trajectory has no poses");
    // Direction at each end: over the first/last 5 m, or the vehicle's heading if it never moves.
    auto endDirection = [&](bool at_start) -> Vec2 {
      const int n = static_cast<int>(raw.size());
      const PathVertex& e = at_start ? raw.front() : raw.back();
      for (int k = 1; k < n; ++k) {
        const PathVertex& q = at_start ? raw[k] : raw[n - 1 - k];
        const Vec2 d(e.x - q.x, e.y - q.y);
        if (d.norm() >= 5.0 || k == n - 1) return d.normalized();
      }
      const Mat4d& P = at_start ? poses.front() : poses.back();
      Vec2 h(P(0, 0), P(1, 0));
      if (h.norm() < 1e-6) h = Vec2(1, 0);
      return (at_start ? -1.0 : 1.0) * h.normalized();
    };
    const Vec2 d0 = endDirection(true), d1 = endDirection(false);
    const int n_ext = static_cast<int>(std::ceil(extension));
    v_.clear();
    for (int k = n_ext; k >= 1; --k)
      v_.push_back({raw.front().x + d0.x() * k, raw.front().y + d0.y() * k, raw.front().z, 0.0});
    v_.insert(v_.end(), raw.begin(), raw.end());
    for (int k = 1; k <= n_ext; ++k)
      v_.push_back({raw.back().x + d1.x() * k, raw.back().y + d1.y() * k, raw.back().z, 0.0});
    for (std::size_t k = 1; k < v_.size(); ++k)
      v_[k].s = v_[k - 1].s + std::hypot(v_[k].x - v_[k - 1].x, v_[k].y - v_[k - 1].y);
    // Gaussian smoothing of the height along the path (sigma 5 m): GPS jitter must not make bumps.
    std::vector<double> z(v_.size());
    for (std::size_t k = 0; k < v_.size(); ++k) {
      double acc = 0, wsum = 0;
      for (std::size_t j = k; j-- > 0 && v_[k].s - v_[j].s < 15.0;) {
        const double w = std::exp(-0.5 * std::pow((v_[k].s - v_[j].s) / 5.0, 2));
        acc += w * v_[j].z;
        wsum += w;
      }
      for (std::size_t j = k; j < v_.size() && v_[j].s - v_[k].s < 15.0; ++j) {
        const double w = std::exp(-0.5 * std::pow((v_[j].s - v_[k].s) / 5.0, 2));
        acc += w * v_[j].z;
        wsum += w;
      }
      z[k] = acc / wsum;
    }
    for (std::size_t k = 0; k < v_.size(); ++k) v_[k].z = z[k];
    buildIndex();
  }

  const std::vector<PathVertex>& vertices() const { return v_; }
  double length() const { return v_.back().s; }
  int segments() const { return static_cast<int>(v_.size()) - 1; }
  Vec2 vertex(int k) const { return {v_[k].x, v_[k].y}; }

  Vec2 point(double s) const {
    const auto [k, u] = locate(s);
    return Vec2(v_[k].x, v_[k].y) * (1 - u) + Vec2(v_[k + 1].x, v_[k + 1].y) * u;
  }
  double height(double s) const {
    const auto [k, u] = locate(s);
    return v_[k].z * (1 - u) + v_[k + 1].z * u;
  }
  // Unit tangent, smoothed over +-4 m so that GPS jitter does not turn it.
  Vec2 tangent(double s) const {
    Vec2 d = point(std::min(s + 4.0, length())) - point(std::max(s - 4.0, 0.0));
    if (d.norm() < 1e-9) d = vertex(1) - vertex(0);
    return d.normalized();
  }

  struct Nearest {
    double dist = std::numeric_limits<double>::infinity();
    double s = 0.0;
  };
  // Exact distance to the polyline within max_dist (infinite distance if nothing is that close).
  Nearest nearest(double x, double y, double max_dist) const {
    Nearest best;
    const Vec2 p(x, y);
    const int cx = static_cast<int>(std::floor((x - gx0_) / kSegmentCell));
    const int cy = static_cast<int>(std::floor((y - gy0_) / kSegmentCell));
    const int max_ring = static_cast<int>(std::ceil(max_dist / kSegmentCell)) + 1;
    for (int ring = 0; ring <= max_ring; ++ring) {
      // Segments not yet seen lie entirely in rings > ring - 1, so at least (ring - 1) cells away.
      if (best.dist <= (ring - 1) * kSegmentCell) break;
      for (int iy = cy - ring; iy <= cy + ring; ++iy)
        for (int ix = cx - ring; ix <= cx + ring; ++ix) {
          if (std::max(std::abs(ix - cx), std::abs(iy - cy)) != ring) continue;
          if (ix < 0 || iy < 0 || ix >= gnx_ || iy >= gny_) continue;
          const int c = iy * gnx_ + ix;
          for (int q = cell_start_[c]; q < cell_start_[c + 1]; ++q) {
            const int k = cell_seg_[q];
            double u;
            const double d = segmentDistance(p, vertex(k), vertex(k + 1), &u);
            if (d < best.dist) {
              best.dist = d;
              best.s = v_[k].s + u * (v_[k + 1].s - v_[k].s);
            }
          }
        }
    }
    if (best.dist > max_dist) best = Nearest{};
    return best;
  }

  std::size_t memoryBytes() const {
    return v_.size() * sizeof(PathVertex) + (cell_start_.size() + cell_seg_.size()) * sizeof(int);
  }

 private:
  std::pair<int, double> locate(double s) const {
    s = std::clamp(s, 0.0, length());
    auto it = std::upper_bound(v_.begin(), v_.end(), s, [](double v, const PathVertex& a) { return v < a.s; });
    int k = static_cast<int>(it - v_.begin()) - 1;
    k = std::clamp(k, 0, segments() - 1);
    const double len = v_[k + 1].s - v_[k].s;
    return {k, len > 0 ? std::clamp((s - v_[k].s) / len, 0.0, 1.0) : 0.0};
  }

  void buildIndex() {
    double xmin = 1e300, ymin = 1e300, xmax = -1e300, ymax = -1e300;
    for (const auto& v : v_) {
      xmin = std::min(xmin, v.x);
      ymin = std::min(ymin, v.y);
      xmax = std::max(xmax, v.x);
      ymax = std::max(ymax, v.y);
    }
    gx0_ = xmin - kSegmentCell;
    gy0_ = ymin - kSegmentCell;
    gnx_ = static_cast<int>((xmax - gx0_) / kSegmentCell) + 2;
    gny_ = static_cast<int>((ymax - gy0_) / kSegmentCell) + 2;
    std::vector<int> count(static_cast<std::size_t>(gnx_) * gny_ + 1, 0);
    auto forCells = [&](int k, auto&& fn) {
      const int x0 = static_cast<int>(std::floor((std::min(v_[k].x, v_[k + 1].x) - gx0_) / kSegmentCell));
      const int x1 = static_cast<int>(std::floor((std::max(v_[k].x, v_[k + 1].x) - gx0_) / kSegmentCell));
      const int y0 = static_cast<int>(std::floor((std::min(v_[k].y, v_[k + 1].y) - gy0_) / kSegmentCell));
      const int y1 = static_cast<int>(std::floor((std::max(v_[k].y, v_[k + 1].y) - gy0_) / kSegmentCell));
      for (int iy = y0; iy <= y1; ++iy)
        for (int ix = x0; ix <= x1; ++ix) fn(iy * gnx_ + ix);
    };
    for (int k = 0; k < segments(); ++k) forCells(k, [&](int c) { ++count[c + 1]; });
    for (std::size_t c = 1; c < count.size(); ++c) count[c] += count[c - 1];
    cell_start_ = count;
    cell_seg_.assign(count.back(), 0);
    for (int k = 0; k < segments(); ++k) forCells(k, [&](int c) { cell_seg_[count[c]++] = k; });
  }

  std::vector<PathVertex> v_;
  double gx0_ = 0, gy0_ = 0;
  int gnx_ = 0, gny_ = 0;
  std::vector<int> cell_start_, cell_seg_;
};

struct DistrictInfo {
  District type;
  bool parking;
  std::uint32_t lot_ground;
  std::uint32_t verge;  // the parking strip's class where the district has no parking
};

// A moving agent drives (or walks) along the path at constant speed; its pose is a function of time.
struct Agent {
  double s0 = 0, speed = 0;  // arc length at t = 0 (m), speed (m/s)
  int dir = 1;               // +1 along the path, -1 against it
  double offset = 0;         // lateral offset, positive to the left of the path direction (m)
  float length = 0, width = 0, height = 0;
  std::uint8_t kind = 0;  // 0 car, 1 truck, 2 other vehicle, 3 person
  std::uint32_t label = 0;
  float reflectivity = 0.2f;
};

enum VehicleKind : std::uint8_t { kCarKind = 0, kTruckKind = 1, kOtherKind = 2, kPersonKind = 3 };

Primitive makeBox(double cx, double cy, const Vec2& axis, double hx, double hy, double z0, double z1,
                  std::uint32_t label, double reflectivity) {
  Primitive p;
  p.shape = Shape::kBox;
  p.cx = cx;
  p.cy = cy;
  p.cos_yaw = static_cast<float>(axis.x());
  p.sin_yaw = static_cast<float>(axis.y());
  p.hx = static_cast<float>(hx);
  p.hy = static_cast<float>(hy);
  p.z0 = static_cast<float>(z0);
  p.z1 = static_cast<float>(z1);
  p.label = label;
  p.reflectivity = static_cast<float>(reflectivity);
  p.radius = static_cast<float>(std::hypot(hx, hy));
  return p;
}

Primitive makeCylinder(double cx, double cy, double r, double z0, double z1, std::uint32_t label, double reflectivity) {
  Primitive p;
  p.shape = Shape::kCylinder;
  p.cx = cx;
  p.cy = cy;
  p.hx = p.hy = static_cast<float>(r);
  p.z0 = static_cast<float>(z0);
  p.z1 = static_cast<float>(z1);
  p.label = label;
  p.reflectivity = static_cast<float>(reflectivity);
  p.radius = static_cast<float>(r);
  return p;
}

Primitive makeEllipsoid(double cx, double cy, double cz, double rx, double ry, double rz, std::uint32_t label,
                        double reflectivity) {
  Primitive p;
  p.shape = Shape::kEllipsoid;
  p.cx = cx;
  p.cy = cy;
  p.hx = static_cast<float>(rx);
  p.hy = static_cast<float>(ry);
  p.z0 = static_cast<float>(cz - rz);
  p.z1 = static_cast<float>(cz + rz);
  p.label = label;
  p.reflectivity = static_cast<float>(reflectivity);
  p.radius = static_cast<float>(std::max(rx, ry));
  return p;
}

// The solids of one vehicle or person standing on ground height gz, centred at (cx, cy), facing `heading`.
void appendAgentShape(std::vector<Primitive>& out, double cx, double cy, double gz, const Vec2& heading,
                      std::uint8_t kind, double L, double W, double H, std::uint32_t label, double refl) {
  const Vec2 c(cx, cy);
  switch (kind) {
    case kCarKind: {
      const double body_top = 0.22 + 0.5 * H;
      out.push_back(makeBox(cx, cy, heading, L / 2, W / 2, gz + 0.22, gz + body_top, label, refl));
      const Vec2 cab = c - heading * (0.08 * L);
      Primitive glass =
          makeBox(cab.x(), cab.y(), heading, 0.28 * L, 0.46 * W, gz + body_top, gz + H, label, 0.6 * refl);
      glass.flags |= kGlass;
      out.push_back(glass);
      break;
    }
    case kTruckKind: {
      const double cab_len = 2.1;
      const Vec2 cab = c + heading * (L / 2 - cab_len / 2);
      out.push_back(makeBox(cab.x(), cab.y(), heading, cab_len / 2, W / 2, gz + 0.5, gz + 0.85 * H, label, refl));
      const double cargo_len = L - cab_len - 0.2;
      const Vec2 cargo = c - heading * (L / 2 - cargo_len / 2);
      out.push_back(makeBox(cargo.x(), cargo.y(), heading, cargo_len / 2, W / 2, gz + 0.75, gz + H, label, refl));
      break;
    }
    case kOtherKind: {
      out.push_back(makeBox(cx, cy, heading, L / 2, W / 2, gz + 0.3, gz + 0.55 * H, label, refl));
      const Vec2 top = c - heading * (0.05 * L);
      out.push_back(makeBox(top.x(), top.y(), heading, 0.43 * L, 0.48 * W, gz + 0.55 * H, gz + H, label, refl));
      break;
    }
    default:
      out.push_back(makeCylinder(cx, cy, 0.5 * W, gz, gz + H, label, refl));
      break;
  }
}

std::uint64_t bitsOf(double v) {
  std::uint64_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}
std::uint64_t bitsOf(float v) {
  std::uint32_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

}  // namespace

const char* districtName(District d) {
  switch (d) {
    case District::kUrban:
      return "urban";
    case District::kResidential:
      return "residential";
    case District::kGreen:
      return "green";
    case District::kIndustrial:
      return "industrial";
  }
  return "?";
}

struct World::Impl {
  std::uint64_t seed = 0;
  WorldConfig config;
  WorldStyle style;
  WorldStats stats;
  Path path;
  TiledGrid<float> dist;    // distance to the path, 1 m cells, clamped at kFar
  TiledGrid<float> height;  // ground height, 4 m cells
  double district_ox = 0, district_oy = 0;
  std::vector<Primitive> prims;
  std::vector<Agent> agents;
  // Static primitive index: uniform grid, CSR, each primitive in the cell of its centre.
  double ix0 = 0, iy0 = 0;
  int inx = 0, iny = 0;
  std::vector<int> index_start, index_ids;
  float max_radius = 0;
  std::uint32_t next_instance = 0;
  // Time-varying primitives: Primitive::presence indexes `presences` (entry 0 unused), which names an
  // occupancy process and the candidate that must be its occupant for the primitive to be there.
  struct Presence {
    std::uint32_t process;
    std::uint8_t candidate;
  };
  std::vector<OccupancyProcess> processes;
  std::vector<Presence> presences{{0, 0}};

  DistrictInfo districtAt(double x, double y) const {
    const auto cx = static_cast<std::int64_t>(std::floor((x - district_ox) / kDistrictCell));
    const auto cy = static_cast<std::int64_t>(std::floor((y - district_oy) / kDistrictCell));
    const std::uint64_t h = hashKeys(seed, kDistrictStream, cx, cy);
    const double u = unitFromBits(h);
    DistrictInfo d;
    // Mostly residential and urban streets, as along the KITTI odometry routes.
    d.type = u < 0.5    ? District::kResidential
             : u < 0.8  ? District::kUrban
             : u < 0.92 ? District::kGreen
                        : District::kIndustrial;
    static constexpr double kParking[4] = {0.85, 0.9, 0.3, 0.5};
    d.parking = unitFromBits(mix64(h)) < kParking[static_cast<int>(d.type)];
    static constexpr std::uint32_t kLotGround[4] = {label::kSidewalk, label::kTerrain, label::kTerrain,
                                                    label::kParking};
    d.lot_ground = kLotGround[static_cast<int>(d.type)];
    static constexpr std::uint32_t kVerge[4] = {label::kSidewalk, label::kTerrain, label::kTerrain, label::kRoad};
    d.verge = kVerge[static_cast<int>(d.type)];
    return d;
  }

  std::uint32_t newInstance() { return (next_instance++ % 65535u) + 1u; }
  static std::uint32_t withInstance(std::uint32_t cls, std::uint32_t inst) { return cls | (inst << 16); }
};

namespace {

// Builds the static content. Passes run in a fixed order (buildings, fences/hedges, kerb furniture, yards,
// parked vehicles); an occupancy raster keeps later objects out of earlier ones, so a place visited twice
// by the trajectory gets one consistent set of objects.
class Generator {
 public:
  explicit Generator(World::Impl& w)
      : w_(w),
        occ_(w.dist.centreX(0) - 0.5 * kDistCell, w.dist.centreY(0) - 0.5 * kDistCell, kDistCell, w.dist.nx(),
             w.dist.ny(), 0) {}

  void run() {
    makeLots();
    for (const auto& lot : lots_) buildings(lot, false);
    for (const auto& lot : lots_) buildings(lot, true);
    for (const auto& lot : lots_) frontBoundary(lot);
    for (int side : {-1, 1}) kerbFurniture(side);
    for (const auto& lot : lots_)
      if (lot.aliased) aliasedKerb(lot);
    for (const auto& lot : lots_) yard(lot);
    if (w_.config.turnover) today_occ_ = occ_;
    for (int side : {-1, 1}) parkedVehicles(side);
    for (const auto& lot : lots_)
      if (lot.aliased) aliasedParking(lot);
    for (const auto& lot : lots_) lotVehicles(lot);
    if (w_.config.turnover)
      for (int side : {-1, 1}) temporaryObjects(side);
    if (w_.config.moving_objects) movingAgents();
    // Vehicles that are not in today's world get their instance ids last, so that today's keep theirs.
    for (const auto& [first, last] : deferred_) {
      const std::uint32_t inst = w_.newInstance();
      for (std::size_t i = first; i < last; ++i) w_.prims[i].label = World::Impl::withInstance(w_.prims[i].label, inst);
    }
  }

 private:
  enum LotKind { kBuildingLot, kGardenLot, kParkLot, kParkingLot, kPlazaLot };
  struct Lot {
    int side;
    double s, len;
    District district;
    LotKind kind;
    double setback;
    int boundary;  // 0 none, 1 fence, 2 hedge
    std::uint64_t key;
    bool aliased = false;  // copies a template (look-alike street)
  };

  const WorldStyle& st() const { return w_.style; }
  double dist(const Vec2& p) const { return w_.dist.bilinear(p.x(), p.y()); }
  double ground(const Vec2& p) const { return w_.height.bilinear(p.x(), p.y()); }

  // Smallest band distance over an oriented rectangle (centre c, unit axis u, half sizes hl along u, hw across).
  double minDistRect(const Vec2& c, const Vec2& u, double hl, double hw) const {
    const Vec2 v = leftNormal(u);
    const int na = std::max(1, static_cast<int>(std::ceil(2 * hl / 1.5)));
    const int nb = std::max(1, static_cast<int>(std::ceil(2 * hw / 1.5)));
    double m = kFar;
    for (int i = 0; i <= na; ++i)
      for (int j = 0; j <= nb; ++j) {
        const Vec2 p = c + u * (-hl + 2 * hl * i / na) + v * (-hw + 2 * hw * j / nb);
        m = std::min(m, dist(p));
      }
    return m;
  }

  template <class Fn>
  void forRectCells(const Vec2& c, const Vec2& u, double hl, double hw, Fn&& fn) {
    const Vec2 v = leftNormal(u);
    const double ex = std::abs(u.x()) * hl + std::abs(v.x()) * hw, ey = std::abs(u.y()) * hl + std::abs(v.y()) * hw;
    const int x0 = occ_.cellX(c.x() - ex), x1 = occ_.cellX(c.x() + ex);
    const int y0 = occ_.cellY(c.y() - ey), y1 = occ_.cellY(c.y() + ey);
    for (int iy = y0; iy <= y1; ++iy)
      for (int ix = x0; ix <= x1; ++ix) {
        const Vec2 q = Vec2(occ_.centreX(ix), occ_.centreY(iy)) - c;
        if (std::abs(q.dot(u)) <= hl && std::abs(q.dot(v)) <= hw && occ_.inside(ix, iy)) fn(ix, iy);
      }
    const int ix = occ_.cellX(c.x()), iy = occ_.cellY(c.y());
    if (occ_.inside(ix, iy)) fn(ix, iy);
  }
  bool freeRect(const Vec2& c, const Vec2& u, double hl, double hw, double margin) {
    return freeRect(c, u, hl, hw, margin, occ_);
  }
  // Same, in another raster of the same layout.
  bool freeRect(const Vec2& c, const Vec2& u, double hl, double hw, double margin, const TiledGrid<std::uint8_t>& g) {
    bool free = true;
    forRectCells(c, u, hl + margin, hw + margin, [&](int ix, int iy) { free = free && g.get(ix, iy) == 0; });
    return free;
  }
  void markRect(const Vec2& c, const Vec2& u, double hl, double hw) {
    forRectCells(c, u, hl, hw, [&](int ix, int iy) { occ_.at(ix, iy) = 1; });
  }
  // The object belongs to this stretch of the path, not to another pass of the trajectory nearby.
  bool owned(const Vec2& p, double s_lo, double s_hi) const {
    const auto n = w_.path.nearest(p.x(), p.y(), 80.0);
    return std::isfinite(n.dist) && n.s >= s_lo && n.s <= s_hi;
  }

  void add(const Primitive& p) { w_.prims.push_back(p); }
  // Foliage pass-through in the world's season (summer, i.e. today's value, when the world is frozen).
  std::uint8_t porosity(std::uint8_t summer, std::uint8_t winter) const {
    return w_.config.turnover ? seasonalPassThrough(summer, winter, w_.config.epoch) : summer;
  }

  // ---- lots: consecutive stretches along each side of the path, each with one kind of content.
  void makeLots() {
    const double S = w_.path.length();
    for (int side : {-1, 1}) {
      Rng rng(hashKeys(w_.seed, kLots, side + 2));
      double s = rng.uniform(0.0, 8.0);
      int k = 0;
      while (s < S - 4.0) {
        const Vec2 p = w_.path.point(s);
        const Vec2 n = side * leftNormal(w_.path.tangent(s));
        const DistrictInfo d =
            w_.districtAt(p.x() + n.x() * (st().lotLine() + 10), p.y() + n.y() * (st().lotLine() + 10));
        Lot lot{side, s, 0, d.type, kBuildingLot, 0, 0, hashKeys(w_.seed, kLots, side + 2, k)};
        drawLot(lot, rng);
        // A look-alike lot: the same draws from its template's stream instead (the lot's own draws above
        // are still made, so that the other lots stay as they are).
        if (const std::uint64_t tkey = lotTemplateKey(w_.seed, side, k, static_cast<int>(d.type), w_.config.aliasing)) {
          Rng trng(tkey);
          drawLot(lot, trng);
          lot.key = hashKeys(tkey, kLots);
          lot.aliased = true;
          aliased_[side > 0].emplace_back(s, s + lot.len);
          ++w_.stats.aliased_lots;
        }
        ++k;
        lot.len = std::min(lot.len, S - s);
        lots_.push_back(lot);
        s += lot.len;
      }
    }
    // Interleave both sides along the path, so that a revisit's objects come after the first visit's.
    std::stable_sort(lots_.begin(), lots_.end(), [](const Lot& a, const Lot& b) { return a.s < b.s; });
  }

  // Length, kind, setback and boundary of a lot of type lot.district.
  static void drawLot(Lot& lot, Rng& rng) {
    const double u = rng.unit();
    switch (lot.district) {
      case District::kUrban:
        lot.len = rng.uniform(12, 28);
        lot.kind = u < 0.88 ? kBuildingLot : u < 0.94 ? kParkingLot : kPlazaLot;
        lot.setback = rng.uniform(0.0, 1.0);
        break;
      case District::kResidential:
        lot.len = rng.uniform(10, 18);
        lot.kind = u < 0.95 ? kBuildingLot : kGardenLot;
        lot.setback = rng.uniform(0.5, 3.0);
        lot.boundary = rng.chance(0.2) ? 1 : rng.chance(0.7) ? 2 : 0;
        break;
      case District::kGreen:
        lot.len = rng.uniform(15, 40);
        lot.kind = u < 0.85 ? kParkLot : kBuildingLot;
        lot.setback = rng.uniform(8, 20);
        lot.boundary = rng.chance(0.3) ? 2 : rng.chance(0.2) ? 1 : 0;
        break;
      case District::kIndustrial:
        lot.len = rng.uniform(25, 50);
        lot.kind = u < 0.7 ? kBuildingLot : kParkingLot;
        lot.setback = rng.uniform(4, 12);
        lot.boundary = rng.chance(0.6) ? 1 : 0;
        break;
    }
  }

  struct LotFrame {
    Vec2 p0, u, n;
    double chord;
  };
  bool lotFrame(const Lot& lot, LotFrame& f) const {
    f.p0 = w_.path.point(lot.s);
    const Vec2 p1 = w_.path.point(lot.s + lot.len);
    f.chord = (p1 - f.p0).norm();
    if (f.chord < 0.6 * lot.len || f.chord < 4.0) return false;  // a sharp bend: no rigid frontage here
    f.u = (p1 - f.p0) / f.chord;
    f.n = lot.side * leftNormal(f.u);
    return true;
  }

  // A box building whose street face is `setback` behind the lot line; pushed or pulled along the lot
  // normal so that its nearest point keeps that distance from the road even where the path bends.
  bool placeBuilding(const Lot& lot, const LotFrame& f, double a_mid, double length, double front, double depth,
                     double height, Rng& rng) {
    Vec2 c = f.p0 + f.u * a_mid + f.n * (front + depth / 2);
    double dmin = kFar;
    for (int i = 0; i <= 8; ++i) {
      const Vec2 q = c + f.u * (-length / 2 + length * i / 8) - f.n * (depth / 2);
      dmin = std::min(dmin, dist(q));
    }
    if (dmin < kFar) c += f.n * std::clamp(front - dmin, -4.0, 8.0);
    if (minDistRect(c, f.u, length / 2, depth / 2) < st().lotLine() - 0.1) return false;
    if (!freeRect(c, f.u, length / 2, depth / 2, 0.05)) return false;
    if (!owned(c - f.n * (depth / 2), lot.s - 20, lot.s + lot.len + 20)) return false;
    double gmin = 1e9;
    for (int sx : {-1, 1})
      for (int sy : {-1, 1}) gmin = std::min(gmin, ground(c + f.u * (sx * length / 2) + f.n * (sy * depth / 2)));
    const double gz = ground(c);
    Primitive b = makeBox(c.x(), c.y(), f.u, length / 2, depth / 2, gmin - 0.5, gz + height, label::kBuilding,
                          rng.uniform(0.25, 0.45));
    b.flags |= kWindows;
    add(b);
    markRect(c, f.u, length / 2, depth / 2);
    ++w_.stats.buildings;
    return true;
  }

  // First row on the street (second_row false), or a building behind it (true), in separate passes so that a
  // second row never takes the place of the next lot's frontage.
  void buildings(const Lot& lot, bool second_row) {
    if (lot.kind != kBuildingLot) return;
    LotFrame f;
    if (!lotFrame(lot, f)) return;
    Rng rng(hashKeys(lot.key, kBuildings, second_row ? 2 : 1));
    const double L0 = st().lotLine();
    double length, depth, height, a_mid;
    switch (lot.district) {
      case District::kUrban:
        length = f.chord - rng.uniform(0.0, 2.0);
        depth = rng.uniform(10, 18);
        height = rng.uniform(12, 25);
        a_mid = f.chord / 2;
        break;
      case District::kResidential:
        length = f.chord - rng.uniform(0.5, 4.0);
        depth = rng.uniform(9, 14);
        height = rng.uniform(9, 18);
        a_mid = f.chord / 2 + rng.uniform(-1, 1) * (f.chord - length) / 2 * 0.7;
        break;
      case District::kIndustrial:
        length = f.chord - rng.uniform(3, 8);
        depth = rng.uniform(15, 30);
        height = rng.uniform(6, 12);
        a_mid = f.chord / 2;
        break;
      default:
        length = std::min(rng.uniform(10, 20), f.chord - 4);
        depth = rng.uniform(10, 15);
        height = rng.uniform(5, 12);
        a_mid = f.chord / 2;
        break;
    }
    if (length < 5) return;
    const double front = L0 + lot.setback;
    if (!second_row) {
      // Corners, bends and shallow blocks: try a shallower, then a shorter building.
      if (!placeBuilding(lot, f, a_mid, length, front, depth, height, rng) &&
          !placeBuilding(lot, f, a_mid, length, front, depth * 0.5, height, rng))
        placeBuilding(lot, f, a_mid, length * 0.55, front, depth * 0.5, height, rng);
      return;
    }
    // A second row behind the first, seen over and between the frontage.
    if ((lot.district == District::kUrban || lot.district == District::kResidential) && rng.chance(0.7)) {
      const double front2 = front + depth + rng.uniform(3, 10);
      placeBuilding(lot, f, a_mid + rng.uniform(-3, 3), std::min(rng.uniform(8, 20), f.chord), front2,
                    rng.uniform(8, 14), rng.uniform(6, 18), rng);
    }
  }

  // Fence or hedge along the lot line, following the path's bends in pieces of at most 5 m.
  void frontBoundary(const Lot& lot) {
    if (lot.boundary == 0) return;
    Rng rng(hashKeys(lot.key, kFences));
    const bool fence = lot.boundary == 1;
    const bool industrial = lot.district == District::kIndustrial;
    const double h = fence ? (industrial ? rng.uniform(1.8, 2.3) : rng.uniform(1.0, 1.8)) : rng.uniform(1.2, 2.4);
    const double thick = fence ? 0.05 : rng.uniform(0.7, 1.2);
    const double b = st().lotLine() + 0.15 + thick / 2;
    const double gate_at = rng.uniform(0.2, 0.8) * lot.len, gate = lot.district == District::kResidential ? 3.0 : 0.0;
    const double refl = fence ? rng.uniform(0.2, 0.4) : rng.uniform(0.3, 0.4);
    double a = lot.s + 0.5;
    const double end = lot.s + lot.len - 0.5;
    bool any = false;
    while (a < end - 0.5) {
      double a2 = std::min(a + 5.0, end);
      if (gate > 0 && a < lot.s + gate_at + gate && a2 > lot.s + gate_at) {  // leave an entrance
        if (a < lot.s + gate_at - 0.5)
          a2 = lot.s + gate_at;
        else {
          a = lot.s + gate_at + gate;
          continue;
        }
      }
      const Vec2 P = w_.path.point(a) + lot.side * leftNormal(w_.path.tangent(a)) * b;
      const Vec2 Q = w_.path.point(a2) + lot.side * leftNormal(w_.path.tangent(a2)) * b;
      const double len = (Q - P).norm();
      if (len > 0.3) {
        const Vec2 u = (Q - P) / len, c = (P + Q) / 2;
        const double hl = len / 2 + 0.02, hw = thick / 2;
        if (minDistRect(c, u, hl, hw) >= st().lotLine() - 0.2 && freeRect(c, u, hl, hw, 0.05) &&
            owned(c, lot.s - 20, lot.s + lot.len + 20)) {
          const double gz = ground(c);
          Primitive p =
              makeBox(c.x(), c.y(), u, hl, hw, gz - 0.2, gz + h, fence ? label::kFence : label::kVegetation, refl);
          if (fence)
            p.pass_through = industrial ? 110 : 50;  // mesh and lattice fences let rays through
          else {
            p.pass_through = porosity(30, 70);  // hedges are partly evergreen
            p.depth_jitter = 0.35f;
          }
          add(p);
          markRect(c, u, hl, hw);
          any = true;
        }
      }
      a = a2;
    }
    if (any) ++(fence ? w_.stats.fences : w_.stats.hedges);
  }

  // A tree: trunk (71, an instance) and one or two canopy ellipsoids (70).
  bool placeTree(const Vec2& c, double trunk_r, double trunk_h, double crown_r, double crown_h, double min_dist,
                 double s_lo, double s_hi, Rng& rng) {
    if (dist(c) < min_dist) return false;
    if (!freeRect(c, Vec2(1, 0), trunk_r, trunk_r, 0.8)) return false;
    if (!owned(c, s_lo, s_hi)) return false;
    const double gz = ground(c);
    const std::uint32_t inst = w_.newInstance();
    add(makeCylinder(c.x(), c.y(), trunk_r, gz - 0.2, gz + trunk_h + 0.5 * crown_h,
                     World::Impl::withInstance(label::kTrunk, inst), rng.uniform(0.25, 0.4)));
    auto crown = [&](const Vec2& q, double r, double h, double cz) {
      Primitive p = makeEllipsoid(q.x(), q.y(), cz, r, r, h, label::kVegetation, rng.uniform(0.28, 0.4));
      p.pass_through = porosity(55, 200);  // deciduous crowns: bare twigs in winter
      p.depth_jitter = 0.8f;
      add(p);
    };
    const double cz = gz + trunk_h + 0.8 * crown_h;
    crown(c, crown_r, crown_h, cz);
    if (rng.chance(0.4)) {
      const double ang = rng.uniform(0, 2 * std::numbers::pi);
      const Vec2 q = c + Vec2(std::cos(ang), std::sin(ang)) * (0.4 * crown_r);
      crown(q, 0.7 * crown_r, 0.7 * crown_h, cz + 0.3 * crown_h);
    }
    markRect(c, Vec2(1, 0), trunk_r + 0.3, trunk_r + 0.3);
    ++w_.stats.trees;
    return true;
  }

  bool placeBush(const Vec2& c, double r, double h, double min_dist, double s_lo, double s_hi, Rng& rng) {
    if (dist(c) < min_dist + r) return false;
    if (!freeRect(c, Vec2(1, 0), r * 0.7, r * 0.7, 0.1)) return false;
    if (!owned(c, s_lo, s_hi)) return false;
    const double gz = ground(c);
    Primitive p = makeEllipsoid(c.x(), c.y(), gz + 0.55 * h, r, r * rng.uniform(0.7, 1.0), h, label::kVegetation,
                                rng.uniform(0.3, 0.4));
    p.pass_through = porosity(25, 110);
    p.depth_jitter = 0.3f;
    add(p);
    markRect(c, Vec2(1, 0), r * 0.7, r * 0.7);
    ++w_.stats.bushes;
    return true;
  }

  bool placeLamp(int side, double s, double r, double h, double arm, Rng& rng) {
    const double kerb = st().kerb();
    const Vec2 t = w_.path.tangent(s), n = side * leftNormal(t);
    const Vec2 c = w_.path.point(s) + n * (kerb + 0.35);
    if (dist(c) < kerb + 0.2 || !freeRect(c, t, 0.3, 0.3, 0.3) || !owned(c, s - 10, s + 10)) return false;
    const double gz = ground(c);
    const std::uint32_t lab = World::Impl::withInstance(label::kPole, w_.newInstance());
    const double refl = rng.uniform(0.25, 0.4);
    add(makeCylinder(c.x(), c.y(), r, gz - 0.2, gz + h, lab, refl));
    const Vec2 ac = c - n * (arm / 2);
    add(makeBox(ac.x(), ac.y(), n, arm / 2, 0.06, gz + h - 0.15, gz + h, lab, refl));
    const Vec2 lc = c - n * (arm + 0.2);
    add(makeBox(lc.x(), lc.y(), n, 0.3, 0.15, gz + h - 0.3, gz + h - 0.05, lab, refl));
    markRect(c, t, 0.3, 0.3);
    ++w_.stats.poles;
    return true;
  }

  // Whether arc length s on `side` lies along a look-alike lot, whose street trees, lamp posts and parked
  // vehicles come from its template (aliasedKerb, aliasedParking) instead of the street-long passes.
  bool aliasedStretch(int side, double s) const {
    for (const auto& [lo, hi] : aliased_[side > 0])
      if (s >= lo && s < hi) return true;
    return false;
  }

  // A look-alike lot's kerb: lamp post and street trees at the template's offsets and spacing.
  void aliasedKerb(const Lot& lot) {
    Rng rng(hashKeys(lot.key, kKerb));
    if (rng.chance(0.6)) {
      const double a = rng.uniform(1, std::max(1.5, lot.len - 1)), r = rng.uniform(0.08, 0.13);
      const double h = rng.uniform(6.0, 9.0), arm = rng.uniform(1.0, 2.0);
      Rng lamp(hashKeys(lot.key, kKerb, 1));
      placeLamp(lot.side, lot.s + a, r, h, arm, lamp);
    }
    if (!rng.chance(kStreetTrees[static_cast<int>(lot.district)] * 1.3)) return;
    const double gap = rng.uniform(6, 12), trunk_r = rng.uniform(0.15, 0.3), trunk_h = rng.uniform(3.0, 4.5);
    const double crown_r = rng.uniform(2.2, 4.0), crown_h = rng.uniform(2.0, 3.2);
    int k = 0;
    for (double a = rng.uniform(1, gap); a < lot.len - 1; a += gap) {
      const double s = lot.s + a;
      const Vec2 c = w_.path.point(s) + lot.side * leftNormal(w_.path.tangent(s)) * (st().kerb() + 0.75);
      Rng tree(hashKeys(lot.key, kKerb, 2, k++));
      placeTree(c, trunk_r, trunk_h, crown_r, crown_h, st().kerb() + 0.3, s - 10, s + 10, tree);
    }
  }

  // Street trees, lamp posts and traffic signs at the kerb side of the sidewalk.
  void kerbFurniture(int side) {
    const double S = w_.path.length();
    const double kerb = st().kerb();
    {
      Rng rng(hashKeys(w_.seed, kKerb, side + 2, 1));
      for (double s = rng.uniform(2, 20); s < S; s += rng.uniform(22, 38)) {
        if (!rng.chance(0.85) || aliasedStretch(side, s)) continue;
        const double r = rng.uniform(0.08, 0.13), h = rng.uniform(6.0, 9.0), arm = rng.uniform(1.0, 2.0);
        placeLamp(side, s, r, h, arm, rng);
      }
    }
    {
      Rng rng(hashKeys(w_.seed, kKerb, side + 2, 2));
      for (double s = rng.uniform(5, 40); s < S; s += rng.uniform(35, 90)) {
        const Vec2 t = w_.path.tangent(s), n = side * leftNormal(t);
        const Vec2 c = w_.path.point(s) + n * (kerb + 0.3);
        if (dist(c) < kerb + 0.15 || !freeRect(c, t, 0.35, 0.2, 0.2) || !owned(c, s - 10, s + 10)) continue;
        const double gz = ground(c), h = rng.uniform(2.3, 2.9);
        add(makeCylinder(c.x(), c.y(), 0.035, gz - 0.2, gz + h,
                         World::Impl::withInstance(label::kPole, w_.newInstance()), rng.uniform(0.25, 0.4)));
        // The plate faces the traffic that approaches on this side (right side: traffic along +t).
        const Vec2 facing = side < 0 ? Vec2(-t) : t;
        const Vec2 pc = c + facing * 0.06;
        const double w = rng.chance(0.7) ? 0.32 : 0.45;
        add(makeBox(pc.x(), pc.y(), facing, 0.015, w, gz + h - 2 * w - 0.05, gz + h,
                    World::Impl::withInstance(label::kTrafficSign, w_.newInstance()), rng.uniform(0.55, 0.8)));
        markRect(c, t, 0.35, 0.2);
        ++w_.stats.signs;
      }
    }
    {
      Rng rng(hashKeys(w_.seed, kKerb, side + 2, 3));
      for (double s = rng.uniform(2, 10); s < S; s += rng.uniform(6, 12)) {
        const Vec2 t = w_.path.tangent(s), n = side * leftNormal(t);
        const Vec2 c = w_.path.point(s) + n * (kerb + 0.75);
        if (!rng.chance(kStreetTrees[static_cast<int>(w_.districtAt(c.x(), c.y()).type)]) || aliasedStretch(side, s))
          continue;
        placeTree(c, rng.uniform(0.15, 0.3), rng.uniform(3.0, 4.5), rng.uniform(2.2, 4.0), rng.uniform(2.0, 3.2),
                  kerb + 0.3, s - 10, s + 10, rng);
      }
    }
    {
      // Street clutter (other-object, 99): bins, boxes, benches, bollards on the sidewalk.
      Rng rng(hashKeys(w_.seed, kKerb, side + 2, 4));
      for (double s = rng.uniform(3, 20); s < S; s += rng.uniform(10, 30)) {
        if (!rng.chance(0.5)) continue;
        const Vec2 t = w_.path.tangent(s), n = side * leftNormal(t);
        const double hl = rng.uniform(0.2, 0.7), hw = rng.uniform(0.2, 0.4), h = rng.uniform(0.6, 1.3);
        const Vec2 c =
            w_.path.point(s) + n * rng.uniform(kerb + 0.4 + hw, std::max(kerb + 0.5 + hw, st().lotLine() - 0.3 - hw));
        if (minDistRect(c, t, hl, hw) < kerb + 0.2 || !freeRect(c, t, hl, hw, 0.2) || !owned(c, s - 10, s + 10))
          continue;
        const double gz = ground(c);
        add(makeBox(c.x(), c.y(), t, hl, hw, gz - 0.1, gz + h, label::kOtherObject, rng.uniform(0.2, 0.5)));
        markRect(c, t, hl, hw);
      }
    }
  }

  // Trees and bushes in gardens, parks, plazas and front yards.
  void yard(const Lot& lot) {
    Rng rng(hashKeys(lot.key, kYards));
    const double L0 = st().lotLine();
    int trees = 0, bushes = 0;
    double depth = 12;
    switch (lot.kind) {
      case kParkLot:
        trees = static_cast<int>(lot.len / 9);
        bushes = static_cast<int>(lot.len / 4);
        depth = 25;
        break;
      case kGardenLot:
        trees = 1 + rng.below(2);
        bushes = 3 + rng.below(3);
        depth = 14;
        break;
      case kPlazaLot:
        trees = 1 + rng.below(3);
        bushes = rng.below(2);
        depth = 10;
        break;
      case kBuildingLot:
        if (lot.setback > 1.0) bushes = 1 + rng.below(4);
        if (lot.setback > 2.5 && rng.chance(0.4)) trees = 1;
        depth = lot.setback;
        break;
      default:
        break;
    }
    for (int k = 0; k < trees; ++k) {
      const double s = lot.s + rng.uniform(1, std::max(1.5, lot.len - 1));
      const Vec2 n = lot.side * leftNormal(w_.path.tangent(s));
      const Vec2 c = w_.path.point(s) + n * (L0 + rng.uniform(1.5, std::max(2.0, depth)));
      placeTree(c, rng.uniform(0.2, 0.45), rng.uniform(1.8, 3.5), rng.uniform(2.0, 4.5), rng.uniform(2.0, 4.0),
                L0 + 0.8, lot.s - 20, lot.s + lot.len + 20, rng);
    }
    for (int k = 0; k < bushes; ++k) {
      const double s = lot.s + rng.uniform(0.5, std::max(1.0, lot.len - 0.5));
      const Vec2 n = lot.side * leftNormal(w_.path.tangent(s));
      const double r = rng.uniform(0.8, 2.0);
      const Vec2 c = w_.path.point(s) + n * (L0 + rng.uniform(0.8, std::max(1.0, depth)));
      placeBush(c, r, rng.uniform(0.6, 1.5), L0, lot.s - 20, lot.s + lot.len + 20, rng);
    }
  }

  struct VehicleDims {
    std::uint8_t kind;
    double L, W, H;
    std::uint32_t cls;
  };
  static VehicleDims drawVehicle(Rng& rng, bool moving) {
    const double u = rng.unit();
    if (u < 0.92)
      return {kCarKind, rng.uniform(3.8, 4.9), rng.uniform(1.7, 1.9), rng.uniform(1.4, 1.6),
              moving ? label::kMovingCar : label::kCar};
    if (u < 0.97)
      return {kOtherKind, rng.uniform(5.0, 6.5), rng.uniform(2.0, 2.2), rng.uniform(2.2, 2.8),
              moving ? label::kMovingOtherVehicle : label::kOtherVehicle};
    return {kTruckKind, rng.uniform(6.5, 8.5), rng.uniform(2.3, 2.5), rng.uniform(2.8, 3.4),
            moving ? label::kMovingTruck : label::kTruck};
  }

  bool placeVehicle(const Vec2& c, const Vec2& heading, const VehicleDims& v, double min_dist, double s_lo, double s_hi,
                    Rng& rng) {
    Candidate q{c, heading, v, 0.0};
    if (!vehicleFits(q, min_dist, s_lo, s_hi, occ_)) return false;
    q.refl = vehicleReflectivity(v, rng);
    appendParked(q);
    return true;
  }

  static constexpr double kOccupied[4] = {0.55, 0.5, 0.3, 0.4};      // share of kerb slots in use, by district
  static constexpr double kStreetTrees[4] = {0.35, 0.5, 0.7, 0.15};  // chance of a kerb tree per step, by district

  // A look-alike lot's parking strip: vehicles at the template's places (with turnover, each comes and goes).
  void aliasedParking(const Lot& lot) {
    Rng rng(hashKeys(lot.key, kParked, 3));
    int k = 0;
    for (double a = rng.uniform(0, 3); a < lot.len; ++k) {
      const VehicleDims v = drawVehicle(rng, false);
      const double gap = rng.uniform(0.8, 4.0), mid = lot.s + a + v.L / 2;
      const Vec2 t = w_.path.tangent(mid), n = lot.side * leftNormal(t);
      const Vec2 c = w_.path.point(mid) + n * (st().road_half_width + st().parking_width / 2 + rng.uniform(-0.15, 0.1));
      const bool occupied = rng.chance(kOccupied[static_cast<int>(lot.district)] + 0.2);
      Candidate q{c, parkedHeading(t, rng), v, vehicleReflectivity(v, rng)};
      a += v.L + gap;
      const DistrictInfo d = w_.districtAt(c.x(), c.y());
      const double s_lo = mid - v.L / 2 - 10, s_hi = mid + v.L / 2 + 10;
      if (a > lot.len || !d.parking || dist(c) > st().kerb() || !occupied ||
          !vehicleFits(q, st().road_half_width - 0.3, s_lo, s_hi, occ_))
        continue;
      if (!w_.config.turnover) {
        appendParked(q);
        continue;
      }
      // Its own stream, so that the template's later vehicles are the frozen world's (day 0 starts from them).
      Rng prng(hashKeys(lot.key, kParked, 4, k, 1));
      addSlot(parkingProcess(hashKeys(lot.key, kParked, 4, k), 0.8, true, 1, prng), {q}, true);
      ++w_.stats.parking_slots;
    }
  }

  // Cars, vans and trucks parked along the parking strip, nose to tail with small gaps.
  void parkedVehicles(int side) {
    const double S = w_.path.length();
    Rng rng(hashKeys(w_.seed, kParked, side + 2));
    double s = rng.uniform(0, 5);
    int slot = 0;
    while (s < S) {
      const VehicleDims v = drawVehicle(rng, false);
      const double gap = rng.uniform(0.8, 4.0), mid = s + v.L / 2;
      const Vec2 t = w_.path.tangent(mid), n = side * leftNormal(t);
      const Vec2 c = w_.path.point(mid) + n * (st().road_half_width + st().parking_width / 2 + rng.uniform(-0.15, 0.1));
      const DistrictInfo d = w_.districtAt(c.x(), c.y());
      const bool occupied = rng.chance(kOccupied[static_cast<int>(d.type)]);
      const Vec2 h = parkedHeading(t, rng);
      if (d.parking && dist(c) <= st().kerb() && !aliasedStretch(side, mid)) {
        if (!w_.config.turnover) {
          if (occupied) placeVehicle(c, h, v, st().road_half_width - 0.3, s - 10, s + v.L + 10, rng);
        } else {
          kerbSlot(side, slot, s, v.L + gap, {c, h, v, 0.0}, occupied, kOccupied[static_cast<int>(d.type)], rng);
        }
      }
      ++slot;
      s += v.L + gap;
    }
  }

  // Parking lots (rows of cars across the lot) and trucks in industrial yards.
  void lotVehicles(const Lot& lot) {
    Rng rng(hashKeys(lot.key, kParked));
    const double L0 = st().lotLine();
    if (lot.kind == kParkingLot) {
      for (int row = 0; row < 2; ++row) {
        const double b = L0 + 1.0 + 2.5 + row * 6.5;
        int bay = 0;
        for (double a = lot.s + 1.5; a < lot.s + lot.len - 1.5; a += rng.uniform(2.5, 2.9), ++bay) {
          const bool occupied = rng.chance(0.65);
          if (w_.config.turnover) {
            lotBay(lot, row, bay, a, b, occupied, rng);
            continue;
          }
          if (!occupied) continue;
          const Vec2 t = w_.path.tangent(a), n = lot.side * leftNormal(t);
          VehicleDims v = drawVehicle(rng, false);
          if (v.kind == kTruckKind) continue;  // trucks do not park in car bays
          v.L = std::min(v.L, 5.0);
          const Vec2 heading = (row == 0) == rng.chance(0.8) ? n : Vec2(-n);
          placeVehicle(w_.path.point(a) + n * b, heading, v, L0 - 0.1, lot.s - 20, lot.s + lot.len + 20, rng);
        }
      }
    } else if (lot.kind == kBuildingLot && lot.district == District::kIndustrial && lot.setback > 6) {
      const int count = 1 + rng.below(2);
      for (int k = 0; k < count; ++k) {
        const double a = lot.s + rng.uniform(5, std::max(6.0, lot.len - 5));
        const Vec2 t = w_.path.tangent(a), n = lot.side * leftNormal(t);
        VehicleDims v = drawVehicle(rng, false);
        if (rng.chance(0.6)) v = {kTruckKind, rng.uniform(6.5, 8.5), 2.45, rng.uniform(3.0, 3.6), label::kTruck};
        placeVehicle(w_.path.point(a) + n * (L0 + 1.5 + v.W / 2), rng.chance(0.5) ? t : Vec2(-t), v, L0 - 0.1,
                     lot.s - 20, lot.s + lot.len + 20, rng);
      }
    }
  }

  // ---- turnover: parking slots and temporary objects whose occupant depends on the time.
  struct Candidate {
    Vec2 c = Vec2::Zero(), heading = Vec2::UnitX();
    VehicleDims v{};  // v.L == 0: no candidate
    double refl = 0.0;
  };
  static double vehicleReflectivity(const VehicleDims& v, Rng& rng) {
    return v.kind == kCarKind ? rng.uniform(0.06, 0.3) : rng.uniform(0.15, 0.4);
  }
  static Vec2 parkedHeading(const Vec2& t, Rng& rng) {
    const double yaw = rng.uniform(-3, 3) * std::numbers::pi / 180 + (rng.chance(0.5) ? 0.0 : std::numbers::pi);
    return {std::cos(yaw) * t.x() - std::sin(yaw) * t.y(), std::sin(yaw) * t.x() + std::cos(yaw) * t.y()};
  }
  // A vehicle of the frozen world: always there, its footprint kept clear of later objects.
  void appendParked(const Candidate& q) {
    appendAgentShape(w_.prims, q.c.x(), q.c.y(), ground(q.c), q.heading, q.v.kind, q.v.L, q.v.W, q.v.H,
                     World::Impl::withInstance(q.v.cls, w_.newInstance()), q.refl);
    markRect(q.c, q.heading, q.v.L / 2, q.v.W / 2);
    ++w_.stats.parked_vehicles;
  }
  bool vehicleFits(const Candidate& k, double min_dist, double s_lo, double s_hi, const TiledGrid<std::uint8_t>& grid) {
    return minDistRect(k.c, k.heading, k.v.L / 2, k.v.W / 2) >= min_dist &&
           freeRect(k.c, k.heading, k.v.L / 2, k.v.W / 2, 0.2, grid) && owned(k.c, s_lo, s_hi);
  }
  // Today's occupant of a slot is tested against today's raster and draws its reflectivity exactly when the
  // frozen world does (so the frozen world's streams stay in step); it is kept if it also fits the full one.
  bool todayOccupant(Candidate& k, double min_dist, double s_lo, double s_hi, Rng& rng) {
    if (!vehicleFits(k, min_dist, s_lo, s_hi, today_occ_)) return false;
    k.refl = vehicleReflectivity(k.v, rng);
    forRectCells(k.c, k.heading, k.v.L / 2, k.v.W / 2, [&](int ix, int iy) { today_occ_.at(ix, iy) = 1; });
    return vehicleFits(k, min_dist, s_lo, s_hi, occ_);
  }

  // Registers a slot's occupancy process and adds its candidates (the index is the candidate id). The
  // candidates may overlap each other, as only one is there at a time, but their footprints are reserved.
  void addSlot(const OccupancyProcess& process, const std::vector<Candidate>& cands, bool today_first) {
    const auto pid = static_cast<std::uint32_t>(w_.processes.size());
    w_.processes.push_back(process);
    for (std::size_t k = 0; k < cands.size(); ++k) {
      const Candidate& q = cands[k];
      if (q.v.L <= 0) continue;
      const auto presence = static_cast<std::uint32_t>(w_.presences.size());
      w_.presences.push_back({pid, static_cast<std::uint8_t>(k)});
      const std::size_t first = w_.prims.size();
      const bool today = k == 0 && today_first;
      appendAgentShape(w_.prims, q.c.x(), q.c.y(), ground(q.c), q.heading, q.v.kind, q.v.L, q.v.W, q.v.H,
                       World::Impl::withInstance(q.v.cls, today ? w_.newInstance() : 0), q.refl);
      for (std::size_t i = first; i < w_.prims.size(); ++i) w_.prims[i].presence = presence;
      if (!today) deferred_.emplace_back(first, w_.prims.size());
      ++w_.stats.parked_vehicles;
    }
    for (const Candidate& q : cands)
      if (q.v.L > 0) markRect(q.c, q.heading, q.v.L / 2, q.v.W / 2);
  }

  OccupancyProcess parkingProcess(std::uint64_t key, double occupancy, bool occupied_today, int candidates,
                                  Rng& rng) const {
    OccupancyProcess p;
    p.key = key;
    p.period = rng.chance(kTurnover.short_stay_share) ? kTurnover.short_stay_period : kTurnover.resident_period;
    p.phase = rng.uniform(0, p.period);
    p.empty = static_cast<float>(1.0 - occupancy);
    p.candidates = static_cast<std::uint8_t>(candidates);
    p.at_zero = occupied_today ? 0 : OccupancyProcess::kEmpty;
    return p;
  }

  // A kerb-side slot (today's vehicle and its gap to the next): today's vehicle as candidate 0 and other
  // vehicles that fit the slot's room, one at a time, as the slot's occupancy process picks them.
  void kerbSlot(int side, int slot, double s, double room, Candidate today, bool occupied, double occupancy, Rng& rng) {
    const double min_dist = st().road_half_width - 0.3;
    Rng srng(hashKeys(w_.seed, kParked, side + 2, slot, 1));
    std::vector<Candidate> cands(kTurnover.candidates, Candidate{});
    bool today_in = false;
    if (occupied) {
      today_in = todayOccupant(today, min_dist, s - 10, s + today.v.L + 10, rng);
      if (today_in) cands[0] = today;
    } else {
      today.refl = vehicleReflectivity(today.v, srng);
      if (vehicleFits(today, min_dist, s - 10, s + today.v.L + 10, occ_)) cands[0] = today;
    }
    const double fit = room - 0.8;  // keeps the frozen world's smallest gap to the next slot
    for (int k = 1; k < kTurnover.candidates; ++k) {
      const VehicleDims v = drawVehicle(srng, false);
      const double mid = s + v.L / 2 + srng.uniform(0, std::max(0.0, fit - v.L));
      const Vec2 t = w_.path.tangent(mid), n = side * leftNormal(t);
      const Vec2 c =
          w_.path.point(mid) + n * (st().road_half_width + st().parking_width / 2 + srng.uniform(-0.15, 0.1));
      const Candidate q{c, parkedHeading(t, srng), v, vehicleReflectivity(v, srng)};
      if (v.L <= fit && vehicleFits(q, min_dist, s - 10, s + v.L + 10, occ_)) cands[k] = q;
    }
    addSlot(
        parkingProcess(hashKeys(w_.seed, kParked, side + 2, slot, 2), occupancy, occupied, kTurnover.candidates, srng),
        cands, today_in);
    ++w_.stats.parking_slots;
  }

  // A bay of a parking lot with turnover (same scheme as kerbSlot).
  void lotBay(const Lot& lot, int row, int bay, double a, double b, bool occupied, Rng& rng) {
    const double L0 = st().lotLine(), s_lo = lot.s - 20, s_hi = lot.s + lot.len + 20;
    const Vec2 t = w_.path.tangent(a), n = lot.side * leftNormal(t);
    std::vector<Candidate> cands(kTurnover.candidates, Candidate{});
    bool today_in = false;
    if (occupied) {  // the frozen world's draws, in its order
      VehicleDims v = drawVehicle(rng, false);
      if (v.kind != kTruckKind) {
        v.L = std::min(v.L, 5.0);
        const Vec2 heading = (row == 0) == rng.chance(0.8) ? n : Vec2(-n);
        Candidate q{w_.path.point(a) + n * b, heading, v, 0.0};
        today_in = todayOccupant(q, L0 - 0.1, s_lo, s_hi, rng);
        if (today_in) cands[0] = q;
      }
    }
    Rng brng(hashKeys(lot.key, kParked, row, bay));
    for (int k = occupied ? 1 : 0; k < kTurnover.candidates; ++k) {
      VehicleDims v = drawVehicle(brng, false);
      v.L = std::min(v.L, 5.0);
      const Vec2 heading = (row == 0) == brng.chance(0.8) ? n : Vec2(-n);
      const Candidate q{w_.path.point(a) + n * b, heading, v, vehicleReflectivity(v, brng)};
      if (v.kind != kTruckKind && vehicleFits(q, L0 - 0.1, s_lo, s_hi, occ_)) cands[k] = q;
    }
    addSlot(parkingProcess(hashKeys(lot.key, kParked, row, bay, 2), 0.65, occupied, kTurnover.candidates, brng), cands,
            today_in);
    ++w_.stats.parking_slots;
  }

  // Skips, construction fences and parked trucks that stay for days to weeks: candidate sites along the
  // sidewalk's outer edge and the parking strip, each in use in some epochs only.
  void temporaryObjects(int side) {
    const double S = w_.path.length();
    Rng rng(hashKeys(w_.seed, kTemporary, side + 2));
    int site = 0;
    for (double s = rng.uniform(5, 30); s < S; s += rng.uniform(25, 55), ++site) {
      const Vec2 t = w_.path.tangent(s), n = side * leftNormal(t);
      const int kind = rng.below(3);
      const double strip = st().road_half_width + st().parking_width / 2;
      const double hl = kind == 0 ? rng.uniform(2.5, 6.0) : kind == 1 ? rng.uniform(1.6, 2.0) : rng.uniform(3.2, 4.2);
      const double hw = kind == 0 ? 0.05 : kind == 1 ? rng.uniform(0.8, 1.0) : 1.225;
      const double h = kind == 0 ? rng.uniform(1.8, 2.1) : kind == 1 ? rng.uniform(1.2, 1.7) : rng.uniform(3.0, 3.6);
      const double refl = rng.uniform(0.2, 0.45);
      const Vec2 c = w_.path.point(s) + n * (kind == 0 ? st().lotLine() - 0.35 : strip);
      const double min_dist = kind == 0 ? st().kerb() + 0.2 : st().road_half_width - 0.3;
      if (minDistRect(c, t, hl, hw) < min_dist || !freeRect(c, t, hl, hw, 0.2, occ_) || !owned(c, s - 10, s + 10))
        continue;
      OccupancyProcess p;
      p.key = hashKeys(w_.seed, kTemporary, side + 2, site, 2);
      p.period = kTurnover.temporary_period;
      p.phase = rng.uniform(0, p.period);
      p.empty = static_cast<float>(1.0 - kTurnover.temporary_presence);
      w_.processes.push_back(p);
      const auto presence = static_cast<std::uint32_t>(w_.presences.size());
      w_.presences.push_back({static_cast<std::uint32_t>(w_.processes.size() - 1), 0});
      const std::size_t first = w_.prims.size();
      const double gz = ground(c);
      if (kind == 2) {
        appendAgentShape(w_.prims, c.x(), c.y(), gz, rng.chance(0.5) ? t : Vec2(-t), kTruckKind, 2 * hl, 2 * hw, h,
                         label::kTruck, refl);
        deferred_.emplace_back(first, w_.prims.size());
      } else {
        Primitive q =
            makeBox(c.x(), c.y(), t, hl, hw, gz - 0.05, gz + h, kind == 0 ? label::kFence : label::kOtherObject, refl);
        q.pass_through = kind == 0 ? 110 : 0;  // mesh panels
        add(q);
      }
      for (std::size_t i = first; i < w_.prims.size(); ++i) w_.prims[i].presence = presence;
      markRect(c, t, hl, hw);
      ++w_.stats.temporary_sites;
    }
  }

  void movingAgents() {
    const double S = w_.path.length();
    Rng rng(hashKeys(w_.seed, kMoving));
    for (double slot = 0; slot < S; slot += 70) {
      if (!rng.chance(0.55)) continue;
      const VehicleDims v = drawVehicle(rng, true);
      Agent a;
      a.s0 = slot + rng.uniform(0, 70);
      a.speed = rng.uniform(4, 12);
      a.dir = rng.chance(0.5) ? 1 : -1;
      // The lane to the left of the driven one, clear of the ego vehicle and of the parked cars.
      a.offset = std::max(2.2, st().road_half_width - 1.1);
      a.length = static_cast<float>(v.L);
      a.width = static_cast<float>(v.W);
      a.height = static_cast<float>(v.H);
      a.kind = v.kind;
      a.label = World::Impl::withInstance(v.cls, w_.newInstance());
      a.reflectivity = static_cast<float>(rng.uniform(0.06, 0.35));
      w_.agents.push_back(a);
    }
    Rng prng(hashKeys(w_.seed, kPeople));
    for (double slot = 0; slot < S; slot += 90) {
      if (!prng.chance(0.5)) continue;
      Agent a;
      a.s0 = slot + prng.uniform(0, 90);
      a.speed = prng.uniform(0.9, 1.6);
      a.dir = prng.chance(0.5) ? 1 : -1;
      a.offset = (prng.chance(0.5) ? 1 : -1) * (st().kerb() + 0.5 * st().sidewalk_width);
      a.width = static_cast<float>(prng.uniform(0.4, 0.55));
      a.length = a.width;
      a.height = static_cast<float>(prng.uniform(1.55, 1.9));
      a.kind = kPersonKind;
      a.label = World::Impl::withInstance(label::kMovingPerson, w_.newInstance());
      a.reflectivity = static_cast<float>(prng.uniform(0.15, 0.4));
      w_.agents.push_back(a);
    }
    w_.stats.moving_agents = w_.agents.size();
  }

  World::Impl& w_;
  TiledGrid<std::uint8_t> occ_;
  std::vector<Lot> lots_;
  // With turnover: the raster as the frozen world would have it (today's objects only), so that today's
  // occupants are tested, and the random streams consumed, exactly as in the frozen world.
  TiledGrid<std::uint8_t> today_occ_;
  std::vector<std::pair<std::size_t, std::size_t>> deferred_;  // primitive ranges whose instance comes last
  std::vector<std::pair<double, double>> aliased_[2];          // look-alike lots' stretches, right / left
};

// The street style (lane and sidewalk widths) and the district grid's offset, drawn from the seed.
void drawStyle(World::Impl& w) {
  Rng rng(hashKeys(w.seed, kStyle));
  w.style.lane_width = rng.uniform(3.0, 3.6);
  w.style.road_half_width = w.style.lane_width + 0.2;
  w.style.parking_width = 2.2;
  w.style.sidewalk_width = rng.uniform(1.5, 2.8);
  w.district_ox = rng.uniform(0, kDistrictCell);
  w.district_oy = rng.uniform(0, kDistrictCell);
}

// The area the rasters and the index cover: the path's bounding box grown by kMargin on every side.
struct Bounds {
  double xmin, ymin, xmax, ymax;
};

Bounds rasterBounds(const Path& path) {
  Bounds b{1e300, 1e300, -1e300, -1e300};
  for (const auto& v : path.vertices()) {
    b.xmin = std::min(b.xmin, v.x);
    b.ymin = std::min(b.ymin, v.y);
    b.xmax = std::max(b.xmax, v.x);
    b.ymax = std::max(b.ymax, v.y);
  }
  b.xmin -= kMargin;
  b.ymin -= kMargin;
  b.xmax += kMargin;
  b.ymax += kMargin;
  return b;
}

// Distance to the path, splatted segment by segment within kFar (cells farther away keep kFar).
void buildDistance(World::Impl& w, const Bounds& b) {
  w.dist = TiledGrid<float>(b.xmin, b.ymin, kDistCell, static_cast<int>((b.xmax - b.xmin) / kDistCell) + 1,
                            static_cast<int>((b.ymax - b.ymin) / kDistCell) + 1, static_cast<float>(kFar));
  for (int k = 0; k < w.path.segments(); ++k) {
    const Vec2 a = w.path.vertex(k), c = w.path.vertex(k + 1);
    const int x0 = w.dist.cellX(std::min(a.x(), c.x()) - kFar), x1 = w.dist.cellX(std::max(a.x(), c.x()) + kFar);
    const int y0 = w.dist.cellY(std::min(a.y(), c.y()) - kFar), y1 = w.dist.cellY(std::max(a.y(), c.y()) + kFar);
    for (int iy = y0; iy <= y1; ++iy)
      for (int ix = x0; ix <= x1; ++ix) {
        if (!w.dist.inside(ix, iy)) continue;
        const double d = segmentDistance(Vec2(w.dist.centreX(ix), w.dist.centreY(iy)), a, c);
        if (d < kFar && d < w.dist.get(ix, iy)) w.dist.at(ix, iy) = static_cast<float>(d);
      }
  }
}

// Ground height: each cell within 24 m of the path takes the Gaussian-weighted (sigma 8 m) mean height of
// the path vertices around it, so the ground follows the road smoothly; farther cells take the height of
// the nearest such cell (breadth-first fill), so the ground stays flat beyond the driven area.
void buildHeight(World::Impl& w, const Bounds& b) {
  const int nx = static_cast<int>((b.xmax - b.xmin) / kHeightCell) + 1,
            ny = static_cast<int>((b.ymax - b.ymin) / kHeightCell) + 1;
  std::vector<double> acc(static_cast<std::size_t>(nx) * ny, 0.0), wsum(acc.size(), 0.0);
  for (const auto& v : w.path.vertices()) {
    const int cx = static_cast<int>((v.x - b.xmin) / kHeightCell), cy = static_cast<int>((v.y - b.ymin) / kHeightCell);
    for (int iy = std::max(0, cy - 6); iy <= std::min(ny - 1, cy + 6); ++iy)
      for (int ix = std::max(0, cx - 6); ix <= std::min(nx - 1, cx + 6); ++ix) {
        const double dx = b.xmin + (ix + 0.5) * kHeightCell - v.x, dy = b.ymin + (iy + 0.5) * kHeightCell - v.y;
        const double d2 = dx * dx + dy * dy;
        if (d2 > 24.0 * 24.0) continue;
        const double wt = std::exp(-d2 / (2 * 8.0 * 8.0));
        acc[iy * nx + ix] += wt * v.z;
        wsum[iy * nx + ix] += wt;
      }
  }
  w.height = TiledGrid<float>(b.xmin, b.ymin, kHeightCell, nx, ny, 0.0f);
  std::vector<char> known(acc.size(), 0);
  std::deque<int> queue;
  for (std::size_t c = 0; c < acc.size(); ++c)
    if (wsum[c] > 1e-9) {
      w.height.at(static_cast<int>(c % nx), static_cast<int>(c / nx)) = static_cast<float>(acc[c] / wsum[c]);
      known[c] = 1;
      queue.push_back(static_cast<int>(c));
    }
  while (!queue.empty()) {
    const int c = queue.front();
    queue.pop_front();
    const int cx = c % nx, cy = c / nx;
    const float h = w.height.get(cx, cy);
    const int nbr[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
    for (const auto& d : nbr) {
      const int x = cx + d[0], y = cy + d[1];
      if (x < 0 || y < 0 || x >= nx || y >= ny || known[y * nx + x]) continue;
      known[y * nx + x] = 1;
      w.height.at(x, y) = h;
      queue.push_back(y * nx + x);
    }
  }
}

// The static index: a uniform kIndexCell grid in CSR form, each primitive in the cell of its centre (queries
// widen their radius by max_radius to find primitives reaching in from neighbouring cells).
void buildIndex(World::Impl& w, const Bounds& b) {
  w.ix0 = b.xmin;
  w.iy0 = b.ymin;
  w.inx = static_cast<int>((b.xmax - b.xmin) / kIndexCell) + 1;
  w.iny = static_cast<int>((b.ymax - b.ymin) / kIndexCell) + 1;
  std::vector<int> count(static_cast<std::size_t>(w.inx) * w.iny + 1, 0);
  auto cellOf = [&](const Primitive& p) {
    const int cx = std::clamp(static_cast<int>((p.cx - w.ix0) / kIndexCell), 0, w.inx - 1);
    const int cy = std::clamp(static_cast<int>((p.cy - w.iy0) / kIndexCell), 0, w.iny - 1);
    return cy * w.inx + cx;
  };
  for (const auto& p : w.prims) {
    ++count[cellOf(p) + 1];
    w.max_radius = std::max(w.max_radius, p.radius);
  }
  for (std::size_t c = 1; c < count.size(); ++c) count[c] += count[c - 1];
  w.index_start = count;
  w.index_ids.assign(w.prims.size(), 0);
  for (std::size_t i = 0; i < w.prims.size(); ++i) w.index_ids[count[cellOf(w.prims[i])]++] = static_cast<int>(i);
}

}  // namespace

World::World(const std::vector<Mat4d>& poses, std::uint64_t seed, const WorldConfig& config)
    : impl_(std::make_unique<Impl>()) {
  const auto t0 = std::chrono::steady_clock::now();
  Impl& w = *impl_;
  if (config.epoch < 0) throw InputError("world: epoch must be >= 0 days, got " + std::to_string(config.epoch));
  if (!(config.aliasing >= 0.0 && config.aliasing <= 1.0))
    throw InputError("world: aliasing must be within [0, 1], got " + std::to_string(config.aliasing));
  w.seed = seed;
  w.config = config;
  drawStyle(w);
  w.path.build(poses, config.sensor_height, config.path_extension);
  w.stats.path_length_m = w.path.length();
  // The rasters first: the generator places objects by distance to the path and on the ground height.
  const Bounds bounds = rasterBounds(w.path);
  buildDistance(w, bounds);
  buildHeight(w, bounds);
  Generator(w).run();
  buildIndex(w, bounds);

  w.stats.primitives = w.prims.size();
  w.stats.memory_bytes = sizeof(Impl) + w.path.memoryBytes() + w.dist.memoryBytes() + w.height.memoryBytes() +
                         w.prims.capacity() * sizeof(Primitive) + w.agents.capacity() * sizeof(Agent) +
                         (w.index_start.size() + w.index_ids.size()) * sizeof(int);
  w.stats.build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

World::~World() = default;
World::World(World&&) noexcept = default;
World& World::operator=(World&&) noexcept = default;

std::uint64_t World::seed() const { return impl_->seed; }
const WorldConfig& World::config() const { return impl_->config; }
const WorldStyle& World::style() const { return impl_->style; }
const WorldStats& World::stats() const { return impl_->stats; }
const std::vector<Primitive>& World::statics() const { return impl_->prims; }

void World::staticsNear(double x, double y, double radius, std::vector<int>& ids) const {
  const Impl& w = *impl_;
  ids.clear();
  const double reach = radius + w.max_radius;
  const int x0 = std::max(0, static_cast<int>(std::floor((x - reach - w.ix0) / kIndexCell)));
  const int x1 = std::min(w.inx - 1, static_cast<int>(std::floor((x + reach - w.ix0) / kIndexCell)));
  const int y0 = std::max(0, static_cast<int>(std::floor((y - reach - w.iy0) / kIndexCell)));
  const int y1 = std::min(w.iny - 1, static_cast<int>(std::floor((y + reach - w.iy0) / kIndexCell)));
  for (int cy = y0; cy <= y1; ++cy)
    for (int cx = x0; cx <= x1; ++cx) {
      const int c = cy * w.inx + cx;
      for (int q = w.index_start[c]; q < w.index_start[c + 1]; ++q) {
        const Primitive& p = w.prims[w.index_ids[q]];
        if (std::hypot(p.cx - x, p.cy - y) - p.radius <= radius) ids.push_back(w.index_ids[q]);
      }
    }
  std::sort(ids.begin(), ids.end());
}

bool World::present(const Primitive& p, double time) const {
  if (p.presence == 0) return true;
  const Impl::Presence& e = impl_->presences[p.presence];
  return occupantAt(impl_->processes[e.process], time) == e.candidate;
}

double World::absoluteTime(double frame_time) const {
  return impl_->config.turnover ? impl_->config.epoch * kSecondsPerDay + frame_time : frame_time;
}

void World::movingNear(double time, double x, double y, double radius, std::vector<Primitive>& out) const {
  const Impl& w = *impl_;
  const double S = w.path.length();
  for (const Agent& a : w.agents) {
    double s = std::fmod(a.s0 + a.dir * a.speed * time, S);
    if (s < 0) s += S;
    const Vec2 t = w.path.tangent(s);
    const Vec2 c = w.path.point(s) + leftNormal(t) * a.offset;
    if ((c - Vec2(x, y)).norm() > radius + a.length) continue;
    const Vec2 heading = a.dir > 0 ? t : Vec2(-t);
    appendAgentShape(out, c.x(), c.y(), w.height.bilinear(c.x(), c.y()), heading, a.kind, a.length, a.width, a.height,
                     a.label, a.reflectivity);
  }
}

double World::groundHeight(double x, double y) const { return impl_->height.bilinear(x, y); }
double World::roadDistance(double x, double y) const { return impl_->dist.bilinear(x, y); }
District World::district(double x, double y) const { return impl_->districtAt(x, y).type; }

std::uint32_t World::groundLabel(double x, double y) const { return groundLabelAt(x, y, impl_->dist.bilinear(x, y)); }

void World::groundPatch(double x, double y, double radius, GroundPatch& patch) const {
  const Impl& w = *impl_;
  auto copy = [&](const TiledGrid<float>& g, double& x0, double& y0, double& cell, int& nx, int& ny,
                  std::vector<float>& v) {
    const int ix0 = g.cellX(x - radius) - 1, ix1 = g.cellX(x + radius) + 2;
    const int iy0 = g.cellY(y - radius) - 1, iy1 = g.cellY(y + radius) + 2;
    cell = g.cell();
    x0 = g.centreX(ix0) - 0.5 * cell;
    y0 = g.centreY(iy0) - 0.5 * cell;
    nx = ix1 - ix0 + 1;
    ny = iy1 - iy0 + 1;
    v.resize(static_cast<std::size_t>(nx) * ny);
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) v[static_cast<std::size_t>(j) * nx + i] = g.get(ix0 + i, iy0 + j);
  };
  copy(w.height, patch.hx0, patch.hy0, patch.hcell, patch.hnx, patch.hny, patch.h);
  copy(w.dist, patch.dx0, patch.dy0, patch.dcell, patch.dnx, patch.dny, patch.d);
  patch.hinv = 1.0 / patch.hcell;
  patch.dinv = 1.0 / patch.dcell;
}

std::uint32_t World::groundLabelAt(double x, double y, double d) const {
  const Impl& w = *impl_;
  if (d < w.style.road_half_width) return label::kRoad;
  const DistrictInfo info = w.districtAt(x, y);
  if (d < w.style.kerb()) return info.parking ? label::kParking : info.verge;
  if (d < w.style.lotLine()) return label::kSidewalk;
  return info.lot_ground;
}

std::uint64_t World::contentHash() const {
  const Impl& w = *impl_;
  std::uint64_t h = hashKeys(w.seed, bitsOf(w.style.lane_width), bitsOf(w.style.sidewalk_width));
  for (const auto& p : w.prims) {
    h = hashKeys(h, static_cast<std::uint64_t>(p.shape), p.flags, p.pass_through, p.label, bitsOf(p.cx), bitsOf(p.cy),
                 bitsOf(p.z0), bitsOf(p.z1), bitsOf(p.hx), bitsOf(p.hy), bitsOf(p.cos_yaw), bitsOf(p.sin_yaw),
                 bitsOf(p.reflectivity), bitsOf(p.depth_jitter));
    if (p.presence != 0) h = hashKeys(h, p.presence);  // only time-varying worlds have any
  }
  for (const auto& q : w.processes)
    h = hashKeys(h, q.key, bitsOf(q.period), bitsOf(q.phase), bitsOf(q.empty), q.candidates,
                 static_cast<std::uint64_t>(q.at_zero + 2));
  for (std::size_t k = 1; k < w.presences.size(); ++k)
    h = hashKeys(h, w.presences[k].process, w.presences[k].candidate);
  for (const auto& a : w.agents)
    h = hashKeys(h, bitsOf(a.s0), bitsOf(a.speed), static_cast<std::uint64_t>(a.dir + 2), bitsOf(a.offset), a.label,
                 bitsOf(a.length));
  return h;
}

}  // namespace sglc::sim
