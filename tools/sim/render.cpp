// Ray casting of one spinning-LiDAR revolution against the world.
//
// Per frame, the primitives near the sensor are gathered once, moved into sensor-centred float coordinates,
// sorted by their horizontal distance, and bucketed into 0.5-degree azimuth sectors. A ray tests only the
// primitives of its sector, nearest first, and stops as soon as the next one cannot be closer than its
// current hit (ground included), so occlusion is exact and cheap. Columns are split between threads; every
// random choice is a hash of (seed, frame, ray), so the output does not depend on the thread count.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <string>
#include <thread>
#include <tuple>
#include <utility>

#include "sim/rng.hpp"
#include "sim/sensor.hpp"
#include "sim/simulator.hpp"

namespace sglc::sim {
namespace {

constexpr int kSectors = 720;
constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kPi = std::numbers::pi_v<float>;

// A primitive in sensor-centred coordinates (world axes, origin at the sensor).
struct LocalPrim {
  float ox, oy;  // box: ray origin in the box frame; cylinder / ellipsoid: -centre (x, y)
  float z0, z1;  // vertical extent relative to the sensor
  float hx, hy;
  float c, s;  // box axis
  float near;  // horizontal distance from the sensor to the bounding circle (>= 0)
  float jitter;
  float reflectivity;
  std::uint32_t label;
  std::uint32_t id;  // stable id: static index, or statics + k for moving parts
  Shape shape;
  std::uint8_t flags;
  std::uint8_t pass;
};

struct Span {
  float t0 = kInf, t1 = kInf;
  int axis = 0;  // box: entry slab (0 x, 1 y, 2 z)
};

// Slab test for one axis; o + t u within [lo, hi].
inline bool slab(float o, float u, float lo, float hi, float& tmin, float& tmax, int axis, int& entry_axis) {
  if (std::abs(u) < 1e-12f) return o >= lo && o <= hi;
  float a = (lo - o) / u, b = (hi - o) / u;
  if (a > b) std::swap(a, b);
  if (a > tmin) {
    tmin = a;
    entry_axis = axis;
  }
  tmax = std::min(tmax, b);
  return tmin <= tmax;
}

// Entry/exit of a ray from the sensor (origin) along unit d; false when missed, behind, or when the sensor is
// inside the solid (its own vehicle's shell, a passing agent).
inline bool intersect(const LocalPrim& p, float dx, float dy, float dz, Span& span) {
  switch (p.shape) {
    case Shape::kBox: {
      const float ux = p.c * dx + p.s * dy, uy = -p.s * dx + p.c * dy;
      float tmin = -kInf, tmax = kInf;
      int axis = 0;
      if (!slab(p.ox, ux, -p.hx, p.hx, tmin, tmax, 0, axis)) return false;
      if (!slab(p.oy, uy, -p.hy, p.hy, tmin, tmax, 1, axis)) return false;
      if (!slab(0.0f, dz, p.z0, p.z1, tmin, tmax, 2, axis)) return false;
      if (tmin <= 0.0f) return false;
      span = {tmin, tmax, axis};
      return true;
    }
    case Shape::kCylinder: {
      const float a = dx * dx + dy * dy;
      if (a < 1e-12f) return false;
      const float b = 2.0f * (p.ox * dx + p.oy * dy);
      const float c = p.ox * p.ox + p.oy * p.oy - p.hx * p.hx;
      if (c <= 0.0f) return false;
      const float disc = b * b - 4.0f * a * c;
      if (disc < 0.0f) return false;
      const float sq = std::sqrt(disc);
      const float t0 = (-b - sq) / (2.0f * a);
      if (t0 <= 0.0f) return false;
      const float z = t0 * dz;
      if (z < p.z0 || z > p.z1) return false;
      span = {t0, (-b + sq) / (2.0f * a), 0};
      return true;
    }
    case Shape::kEllipsoid: {
      const float rz = 0.5f * (p.z1 - p.z0), cz = 0.5f * (p.z1 + p.z0);
      const float qx = p.ox / p.hx, qy = p.oy / p.hy, qz = -cz / rz;
      const float ux = dx / p.hx, uy = dy / p.hy, uz = dz / rz;
      const float a = ux * ux + uy * uy + uz * uz;
      const float b = 2.0f * (qx * ux + qy * uy + qz * uz);
      const float c = qx * qx + qy * qy + qz * qz - 1.0f;
      if (c <= 0.0f) return false;
      const float disc = b * b - 4.0f * a * c;
      if (disc < 0.0f) return false;
      const float sq = std::sqrt(disc);
      const float t0 = (-b - sq) / (2.0f * a);
      if (t0 <= 0.0f) return false;
      span = {t0, (-b + sq) / (2.0f * a), 0};
      return true;
    }
  }
  return false;
}

// Unit surface normal at t (world axes).
inline Vec3f normalAt(const LocalPrim& p, const Vec3f& d, const Span& span, float t) {
  switch (p.shape) {
    case Shape::kBox:
      if (span.axis == 2) return Vec3f::UnitZ();
      return span.axis == 0 ? Vec3f(p.c, p.s, 0.0f) : Vec3f(-p.s, p.c, 0.0f);
    case Shape::kCylinder: {
      const Vec3f n(t * d.x() + p.ox, t * d.y() + p.oy, 0.0f);
      return n.normalized();
    }
    case Shape::kEllipsoid: {
      const float rz = 0.5f * (p.z1 - p.z0), cz = 0.5f * (p.z1 + p.z0);
      const Vec3f n((t * d.x() + p.ox) / (p.hx * p.hx), (t * d.y() + p.oy) / (p.hy * p.hy),
                    (t * d.z() - cz) / (rz * rz));
      return n.normalized();
    }
  }
  return Vec3f::UnitZ();
}

// Is a box hit inside a facade window? A grid of windows 1.3 m wide every 2.6 m, 1.3 m tall every 3 m.
inline bool inWindow(const LocalPrim& p, const Vec3f& d, const Span& span, float t) {
  if (span.axis == 2) return false;
  const float ux = p.c * d.x() + p.s * d.y(), uy = -p.s * d.x() + p.c * d.y();
  const float along = span.axis == 0 ? p.oy + t * uy : p.ox + t * ux;
  const float z = t * d.z() - p.z0;
  const float fz = std::fmod(z, 3.0f), fa = std::fmod(along + 1000.0f, 2.6f);
  return fz > 1.4f && fz < 2.7f && fa > 0.6f && fa < 1.9f;
}

float groundReflectivity(std::uint32_t cls) {
  switch (cls) {
    case label::kRoad:
      return 0.26f;
    case label::kParking:
      return 0.35f;
    case label::kSidewalk:
      return 0.37f;
    case label::kTerrain:
      return 0.42f;
    default:
      return 0.35f;
  }
}

// Smallest t > 0 where the ray from o along d meets the ground height field, or -1. Regula falsi (Illinois)
// on f(t) = z(t) - ground(x(t), y(t)), bracketed by the sensor (above ground) and max range.
// f0 = f(0), the sensor's height above the ground (the same for every ray of a frame).
double groundHit(const GroundPatch& ground, const Vec3d& o, const Vec3d& d, double t_max, double f0) {
  auto f = [&](double t) { return o.z() + t * d.z() - ground.height(o.x() + t * d.x(), o.y() + t * d.y()); };
  if (f0 <= 0.0) return -1.0;
  double a = 0.0, fa = f0, b = t_max, fb;
  // First probe: the flat-ground estimate; it usually brackets the root tightly on one side.
  const double tp = d.z() < 0.0 ? f0 / -d.z() : t_max;
  if (tp < t_max) {
    const double fp = f(tp);
    if (fp > 0.0) {
      a = tp;
      fa = fp;
      fb = f(t_max);
      if (fb > 0.0) return -1.0;
    } else {
      b = tp;
      fb = fp;
    }
  } else {
    fb = f(t_max);
    if (fb > 0.0) return -1.0;
  }
  int side = 0;
  double r = b;
  for (int it = 0; it < 40; ++it) {
    r = (fa * b - fb * a) / (fa - fb);
    const double fr = f(r);
    if (std::abs(fr) < 1e-5 || b - a < 1e-5) break;
    if (fr * fb > 0.0) {
      b = r;
      fb = fr;
      if (side == -1) fa *= 0.5;
      side = -1;
    } else {
      a = r;
      fa = fr;
      if (side == 1) fb *= 0.5;
      side = 1;
    }
  }
  return r;
}

// atan2 with a polynomial (max error ~1e-5 rad); only used to pick a ray's azimuth sector, whose primitive
// lists carry a margin far larger than that.
inline float fastAtan2(float y, float x) {
  const float ax = std::abs(x), ay = std::abs(y);
  const float mx = std::max(ax, ay);
  if (mx == 0.0f) return 0.0f;
  const float z = std::min(ax, ay) / mx, z2 = z * z;
  float r =
      z * (0.99997726f +
           z2 * (-0.33262347f + z2 * (0.19354346f + z2 * (-0.11643287f + z2 * (0.05265332f + z2 * -0.01172120f)))));
  if (ay > ax) r = 0.5f * kPi - r;
  if (x < 0.0f) r = kPi - r;
  return y < 0.0f ? -r : r;
}

// The rear of the ego vehicle (roof end, tailgate) as a sensor-frame box: in KITTI scans the ground within
// about 5.3 m straight behind the car is hidden, elsewhere the lowest beam reaches it at about 4 m.
bool hitsEgoVehicle(const float d[3], float sensor_height) {
  const float ground = -sensor_height;
  const float lo[3] = {-2.7f, -0.9f, ground + 0.25f}, hi[3] = {-0.5f, 0.9f, ground + 0.85f};
  float tmin = 0.0f, tmax = 1e9f;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-9f) {
      if (!(lo[k] <= 0.0f && 0.0f <= hi[k])) return false;
      continue;
    }
    float a = lo[k] / d[k], bb = hi[k] / d[k];
    if (a > bb) std::swap(a, bb);
    tmin = std::max(tmin, a);
    tmax = std::min(tmax, bb);
    if (tmin > tmax) return false;
  }
  return true;
}

// What every ray of a frame shares: the primitives around the sensor by azimuth sector, and the ground.
struct Scene {
  std::vector<LocalPrim> prims;
  std::vector<int> sector_start, sector_items;
  GroundPatch ground;
  double ground_max = 0.0;
  float max_range = 0.0f;
};

}  // namespace

// Where a ray starts: the frame's sensor position, or (motion distortion) the sensor's position when it fires.
struct RayOrigin {
  Vec3d o = Vec3d::Zero();      // world
  double f0 = 0.0;              // height above the ground
  Vec3f shift = Vec3f::Zero();  // o minus the frame's sensor position (the scene's centre)
  float shift_h = 0.0f;         // horizontal length of shift
  Eigen::Matrix3f R;            // sensor -> world rotation
};

namespace {

struct RayHit {
  float t = kInf;
  int prim = -1;  // -1 none, -2 ground, >= 0 index into Scene::prims
  Span span;
};

// The primitive as seen from a sensor moved by s.
inline LocalPrim shiftedPrim(const LocalPrim& p, const Vec3f& s) {
  LocalPrim q = p;
  if (p.shape == Shape::kBox) {
    q.ox += p.c * s.x() + p.s * s.y();
    q.oy += -p.s * s.x() + p.c * s.y();
  } else {
    q.ox += s.x();
    q.oy += s.y();
  }
  q.z0 -= s.z();
  q.z1 -= s.z();
  return q;
}

// Nearest hit along the unit direction d (world axes) from ro. kShifted: ro is not the scene's centre.
template <bool kShifted>
RayHit castRay(const Scene& sc, const RayOrigin& ro, const Vec3f& d, std::uint64_t ray_key) {
  RayHit r;
  const double tg = groundHit(sc.ground, ro.o, d.cast<double>(), sc.ground_max, ro.f0);
  if (tg > 0.0) {
    r.t = static_cast<float>(tg);
    r.prim = -2;
  }
  const float sector_w = 2.0f * kPi / kSectors;
  const float h = std::sqrt(d.x() * d.x() + d.y() * d.y());
  const float slope = h > 1e-6f ? d.z() / h : (d.z() > 0 ? kInf : -kInf);
  const float az = fastAtan2(d.y(), d.x());
  const int sector = std::clamp(static_cast<int>((az + kPi) / sector_w), 0, kSectors - 1);
  const float limit = std::min(r.t, sc.max_range + 1.0f);
  float cutoff = limit * h;  // a primitive whose near distance exceeds best * h cannot be hit earlier
  for (int q = sc.sector_start[sector]; q < sc.sector_start[sector + 1]; ++q) {
    const LocalPrim& p0 = sc.prims[sc.sector_items[q]];
    // Moved by shift_h, the sensor is at least near - shift_h from the primitive (and the order stays).
    const float near = kShifted ? std::max(0.0f, p0.near - ro.shift_h) : p0.near;
    if ((kShifted ? p0.near - ro.shift_h : p0.near) >= cutoff) break;
    LocalPrim moved;
    if constexpr (kShifted) moved = shiftedPrim(p0, ro.shift);
    const LocalPrim& p = kShifted ? moved : p0;
    const float z_near = slope * near;
    if ((d.z() > 0.0f && z_near > p.z1) || (d.z() < 0.0f && z_near < p.z0)) continue;
    Span span;
    if (!intersect(p, d.x(), d.y(), d.z(), span)) continue;
    if (span.t0 >= r.t) continue;
    float t = span.t0;
    if (p.pass || p.jitter > 0.0f) {
      const std::uint64_t hsh = mix64(ray_key ^ p.id);
      if ((hsh & 0xFFu) < p.pass) continue;  // slipped through foliage / a mesh fence
      if (p.jitter > 0.0f)
        t += static_cast<float>(unitFromBits(hsh)) * std::min(p.jitter, std::max(0.0f, span.t1 - span.t0));
      if (t >= r.t) continue;
    }
    r.t = t;
    r.prim = sc.sector_items[q];
    r.span = span;
    cutoff = r.t * h;
  }
  return r;
}

struct Return {
  float range, intensity;
  std::uint32_t label;
};

// The sensor model for a hit: label, incidence, dropout, range noise (plus a laser's range bias), intensity.
// False when there is no return.
template <bool kShifted>
bool sensorReturn(const Scene& sc, const World& world, const SensorConfig& sensor, const RayOrigin& ro, const Vec3f& d,
                  const RayHit& hit, float bias, std::uint64_t ray_key, Return& out) {
  const float best = hit.t, max_range = sc.max_range;
  if (hit.prim == -1 || best > max_range || best < sensor.min_range) return false;
  float refl, cos_inc;
  bool glass = false;
  if (hit.prim == -2) {
    const double gx = ro.o.x() + best * d.x(), gy = ro.o.y() + best * d.y();
    out.label = world.groundLabelAt(gx, gy, sc.ground.distance(gx, gy));
    refl = groundReflectivity(out.label);
    cos_inc = std::abs(d.z());
  } else {
    const LocalPrim& p0 = sc.prims[hit.prim];
    LocalPrim moved;
    if constexpr (kShifted) moved = shiftedPrim(p0, ro.shift);
    const LocalPrim& p = kShifted ? moved : p0;
    out.label = p.label;
    refl = p.reflectivity;
    cos_inc = std::abs(normalAt(p, d, hit.span, best).dot(d));
    glass = (p.flags & kGlass) || ((p.flags & kWindows) && inWindow(p, d, hit.span, best));
  }
  const float rr = best / max_range;
  float p_drop = static_cast<float>(sensor.dropout + sensor.far_dropout * rr * rr);
  if (cos_inc < 0.2f) p_drop += static_cast<float>(sensor.grazing_dropout) * (1.0f - cos_inc / 0.2f);
  if (glass) p_drop += static_cast<float>(sensor.glass_dropout);
  if (p_drop > 0.0f && unitFromBits(mix64(ray_key ^ 0x0D50ULL)) < p_drop) return false;
  float range = best;
  if (bias != 0.0f) range += bias;
  if (sensor.range_noise > 0)
    range += static_cast<float>(sensor.range_noise) * approxNormalFromBits(mix64(ray_key ^ 0x4A7CULL));
  if (range < sensor.min_range || range > max_range) return false;
  float intensity = refl * (0.75f + 0.25f * cos_inc);
  if (sensor.intensity_noise) intensity += 0.03f * approxNormalFromBits(mix64(ray_key ^ 0x1E7ULL));
  out.range = range;
  out.intensity = std::clamp(intensity, 0.0f, 0.99f);
  return true;
}

// ---- per-frame scene: render() gathers the primitives near the sensor and buckets them by azimuth sector

// A world primitive moved into coordinates centred on the sensor at o (world axes).
LocalPrim toLocal(const Primitive& p, std::uint32_t id, const Vec3d& o) {
  LocalPrim q;
  const double rx = p.cx - o.x(), ry = p.cy - o.y();
  q.shape = p.shape;
  q.flags = p.flags;
  q.pass = p.pass_through;
  q.jitter = p.depth_jitter;
  q.reflectivity = p.reflectivity;
  q.label = p.label;
  q.id = id;
  q.hx = p.hx;
  q.hy = p.hy;
  q.c = p.cos_yaw;
  q.s = p.sin_yaw;
  q.z0 = static_cast<float>(p.z0 - o.z());
  q.z1 = static_cast<float>(p.z1 - o.z());
  // A box is tested in its own frame, so store the sensor's position there; round shapes only need the offset.
  if (p.shape == Shape::kBox) {
    q.ox = static_cast<float>(-(p.cos_yaw * rx + p.sin_yaw * ry));
    q.oy = static_cast<float>(-(-p.sin_yaw * rx + p.cos_yaw * ry));
  } else {
    q.ox = static_cast<float>(-rx);
    q.oy = static_cast<float>(-ry);
  }
  q.near = static_cast<float>(std::max(0.0, std::hypot(rx, ry) - p.radius));
  return q;
}

// The static and moving primitives present at `time` whose bounding circle comes within `reach` of o,
// nearest first. Ties are broken by id because std::sort is not stable: the order decides which of two
// equally near primitives a ray tests first, and it must not depend on the world's index layout.
void gatherPrims(const World& world, const Vec3d& o, double time, double reach, std::vector<LocalPrim>& prims) {
  std::vector<int> ids;
  world.staticsNear(o.x(), o.y(), reach, ids);
  std::vector<Primitive> moving;
  world.movingNear(time, o.x(), o.y(), reach, moving);
  const auto& statics = world.statics();
  prims.reserve(ids.size() + moving.size());
  auto keep = [&](const Primitive& p, std::uint32_t id) {
    const LocalPrim q = toLocal(p, id, o);
    if (q.near < static_cast<float>(reach)) prims.push_back(q);
  };
  // Parked vehicles and temporary objects of a world with turnover are there at some times only.
  const double world_time = world.absoluteTime(time);
  for (int id : ids)
    if (statics[id].presence == 0 || world.present(statics[id], world_time))
      keep(statics[id], static_cast<std::uint32_t>(id));
  for (std::size_t k = 0; k < moving.size(); ++k) keep(moving[k], static_cast<std::uint32_t>(statics.size() + k));
  std::sort(prims.begin(), prims.end(),
            [](const LocalPrim& a, const LocalPrim& b) { return a.near != b.near ? a.near < b.near : a.id < b.id; });
}

// Sector k's slot in [0, kSectors): a primitive's sector range may run past either end of the circle.
inline int wrapSector(int k) { return ((k % kSectors) + kSectors) % kSectors; }

// The sectors [first, last] (unwrapped) from which a ray can hit q: the azimuths its bounding circle spans,
// the circle grown by `margin` (how far the sensor moves during the sweep) and the span widened by 0.6 of a
// sector so that a ray near a sector's edge still finds it. All sectors when the sensor is inside or close to
// the circle, where the angle is undefined or wider than half a turn.
std::pair<int, int> sectorSpan(const LocalPrim& q, double margin) {
  const float sector_w = 2.0f * kPi / kSectors;
  // Centre relative to the sensor, from the stored local origin.
  float cx, cy;
  if (q.shape == Shape::kBox) {
    cx = -(q.c * q.ox - q.s * q.oy);
    cy = -(q.s * q.ox + q.c * q.oy);
  } else {
    cx = -q.ox;
    cy = -q.oy;
  }
  const float dist = std::hypot(cx, cy), radius = dist - q.near + static_cast<float>(margin);
  if (q.near <= static_cast<float>(margin) || dist <= radius * 1.0001f) return {0, kSectors - 1};
  const float phi = std::atan2(cy, cx);
  const float alpha = std::asin(std::min(1.0f, radius / dist)) + 0.6f * sector_w;
  if (alpha >= kPi) return {0, kSectors - 1};
  return {static_cast<int>(std::floor((phi - alpha + kPi) / sector_w)),
          static_cast<int>(std::floor((phi + alpha + kPi) / sector_w))};
}

// Sector lists in CSR form (sector k: sector_items[sector_start[k] .. sector_start[k + 1])), each nearest
// first because scene.prims already is: a ray can then stop at the first primitive too far to beat its hit.
void bucketSectors(Scene& scene, double margin) {
  const std::vector<LocalPrim>& prims = scene.prims;
  std::vector<int>& sector_start = scene.sector_start;
  sector_start.assign(kSectors + 1, 0);
  std::vector<int> first(prims.size()), last(prims.size());
  for (std::size_t i = 0; i < prims.size(); ++i) {
    std::tie(first[i], last[i]) = sectorSpan(prims[i], margin);
    for (int k = first[i]; k <= last[i]; ++k) ++sector_start[wrapSector(k) + 1];
  }
  for (int k = 0; k < kSectors; ++k) sector_start[k + 1] += sector_start[k];
  std::vector<int>& sector_items = scene.sector_items;
  sector_items.resize(sector_start[kSectors]);
  std::vector<int> fill(sector_start.begin(), sector_start.end() - 1);
  for (std::size_t i = 0; i < prims.size(); ++i)
    for (int k = first[i]; k <= last[i]; ++k) sector_items[fill[wrapSector(k)]++] = static_cast<int>(i);
}

// The sensor at pose Pk, relative to the frame's sensor position o (the scene's centre).
RayOrigin rayOrigin(const Mat4d& Pk, const Vec3d& o, const GroundPatch& ground) {
  RayOrigin ro;
  ro.o = Pk.topRightCorner<3, 1>();
  ro.f0 = ro.o.z() - ground.height(ro.o.x(), ro.o.y());
  ro.shift = (ro.o - o).cast<float>();
  ro.shift_h = std::hypot(ro.shift.x(), ro.shift.y());
  ro.R = Pk.topLeftCorner<3, 3>().cast<float>();
  return ro;
}

}  // namespace

// Per-frame inputs of the ray loops.
struct Simulator::FrameRays {
  const Scene& scene;
  std::uint64_t frame_key;
  RayOrigin start;                  // the sensor at the sweep's start (the frame's pose)
  std::vector<RayOrigin> sweep;     // motion distortion: the sensor per column / rosette ray; else empty
  std::vector<RosetteRay> rosette;  // rosette: this frame's rays; else empty
};

struct Simulator::RayImage {
  std::vector<float> range, intensity;
  std::vector<std::uint32_t> label;
  std::vector<Vec3f> point;
};

Simulator::Simulator(Trajectory trajectory, SimConfig config)
    : trajectory_(std::move(trajectory)),
      config_(std::move(config)),
      world_(trajectory_.poses, config_.seed, config_.world) {
  // The vehicle drives on the simulated ground. KITTI's GPS/INS heights disagree by up to several metres
  // where a street is driven twice (08: 4 m), and the ground takes a blend of the passes; rendering from the
  // recorded heights would put the sensor metres above or below the road. So every pose keeps its x, y and
  // orientation and gets the nominal sensor height over the ground below it; these are the poses the frames
  // are rendered from and that trajectory() reports as ground truth.
  for (auto& P : trajectory_.poses) P(2, 3) = world_.groundHeight(P(0, 3), P(1, 3)) + config_.world.sensor_height;
  const auto& s = config_.sensor;
  if (s.elevation_deg.empty()) throw InputError("sensor: no beams");
  if (s.elevation_deg.size() > 65535 || s.columns < 8 || s.columns > 65535)
    throw InputError("sensor: beams must be 1..65535 and columns 8..65535");
  if (!(s.max_range > s.min_range) || s.min_range < 0) throw InputError("sensor: need 0 <= min_range < max_range");
  if (s.max_range > 150.0) throw InputError("sensor: max_range above 150 m is not supported (the world ends there)");
  if (trajectory_.frame_dt <= 0) throw InputError("trajectory: frame_dt must be positive");
  for (double e : s.elevation_deg) {
    sin_el_.push_back(static_cast<float>(std::sin(e * std::numbers::pi / 180.0)));
    cos_el_.push_back(static_cast<float>(std::cos(e * std::numbers::pi / 180.0)));
  }
  for (int c = 0; c < s.columns; ++c) {
    const double az = -std::numbers::pi + (c + 0.5) * 2.0 * std::numbers::pi / s.columns;
    sin_az_.push_back(static_cast<float>(std::sin(az)));
    cos_az_.push_back(static_cast<float>(std::cos(az)));
  }
  ego_blocked_.assign(static_cast<std::size_t>(s.columns) * s.beams(), 0);
  if (s.ego_vehicle && !s.isRosette()) {
    const float height = static_cast<float>(config_.world.sensor_height);
    for (int c = 0; c < s.columns; ++c)
      for (int b = 0; b < s.beams(); ++b) {
        const float d[3] = {cos_el_[b] * cos_az_[c], cos_el_[b] * sin_az_[c], sin_el_[b]};
        if (hitsEgoVehicle(d, height)) ego_blocked_[static_cast<std::size_t>(c) * s.beams() + b] = 1;
      }
  }
  if (s.isRosette() && (s.rosette_rays > 4'000'000 || s.rosette_fov_h_deg <= 0 || s.rosette_fov_h_deg >= 180 ||
                        s.rosette_fov_v_deg <= 0 || s.rosette_fov_v_deg >= 180))
    throw InputError("sensor: rosette needs 1..4000000 rays and fields of view in (0, 180) deg");
  if (!(s.mixed_pixel_rate >= 0 && s.mixed_pixel_rate <= 1))  // NaN too
    throw InputError("sensor: mixed_pixel_rate must be in 0..1");
  if (s.laser_offsets) {
    // The lasers' true directions (what the ray is cast along) and range biases; points are still reported
    // along the nominal tables, as an uncorrected sensor would.
    const LaserOffsets off = laserOffsets(s.isRosette() ? std::max(1, s.rosette_channels) : s.beams(), config_.seed);
    laser_el_ = off.elevation_rad;
    laser_az_ = off.azimuth_rad;
    laser_bias_ = off.range_bias_m;
    if (!s.isRosette())
      for (int b = 0; b < s.beams(); ++b) {
        const float se = std::sin(std::asin(sin_el_[b]) + laser_el_[b]);
        true_sin_el_.push_back(se);
        true_cos_el_.push_back(std::sqrt(1.0f - se * se));
        turn_cos_az_.push_back(std::cos(laser_az_[b]));
        turn_sin_az_.push_back(std::sin(laser_az_[b]));
      }
  }
}

Frame Simulator::render(int index) const {
  Frame f;
  render(index, f, config_.threads);
  return f;
}

void Simulator::render(int index, Frame& out, int threads) const {
  if (index < 0 || index >= numFrames())
    throw InputError("frame " + std::to_string(index) + " is outside the trajectory (0.." +
                     std::to_string(numFrames() - 1) + ")");
  const SensorConfig& sensor = config_.sensor;
  const Mat4d& P = trajectory_.poses[index];
  const Vec3d o = P.topRightCorner<3, 1>();
  const double time = index * trajectory_.frame_dt;
  const std::uint64_t frame_key = hashKeys(config_.seed, 0xF4A3E5ULL, static_cast<std::uint64_t>(index));
  // With motion distortion the sensor moves up to `margin` from o during the sweep: gather and bucket with it.
  const std::optional<SweepMotion> sweep =
      sensor.motion_distortion ? std::optional<SweepMotion>(std::in_place, trajectory_.poses, index) : std::nullopt;
  const double margin = sweep ? (sweep->at(1.0).topRightCorner<3, 1>() - o).norm() + 0.01 : 0.0;

  // What all rays share: the primitives around the sensor by sector, and the ground under them.
  Scene scene;
  gatherPrims(world_, o, time, sensor.max_range + margin, scene.prims);
  bucketSectors(scene, margin);
  scene.ground_max = sensor.max_range + 1.0;
  scene.max_range = static_cast<float>(sensor.max_range);
  world_.groundPatch(o.x(), o.y(), scene.ground_max + 2.0 + margin, scene.ground);

  FrameRays fr{scene, frame_key, {}, {}, {}};
  fr.start = rayOrigin(P, o, scene.ground);
  if (sensor.isRosette()) rosetteRays(sensor, config_.seed, index, fr.rosette);
  const int units = sensor.isRosette() ? sensor.rosette_rays : sensor.columns;  // what threads split
  if (sweep) {
    // One pose per column (spinning) or per ray (rosette), at its time within the sweep.
    fr.sweep.resize(static_cast<std::size_t>(units));
    for (int k = 0; k < units; ++k) fr.sweep[k] = rayOrigin(sweep->at(static_cast<double>(k) / units), o, scene.ground);
  }
  RayImage img;
  castImage(fr, units, threads, img);
  // Neighbours across a depth edge: the next column on the same beam, or the next rosette ray.
  out.mixed_points = applyMixedPixels(img.range, img.point, img.label, img.intensity,
                                      sensor.isRosette() ? 1 : static_cast<std::size_t>(sensor.beams()),
                                      !sensor.isRosette(), sensor.mixed_pixel_rate, frame_key);

  out.index = index;
  out.time = time;
  out.pose = P;
  compact(fr, img, out);
  if (config_.label_noise.any())
    applyLabelNoise(out, config_.label_noise, config_.seed, sensor.beams(), sensor.columns, !sensor.isRosette());
}

// Casts every ray of the frame into an image, spinning column-major (pixel = column * beams + beam), rosette
// in firing order. The columns (rays) are split into contiguous blocks, one per thread; every ray writes only
// its own pixel, so the image does not depend on the split.
void Simulator::castImage(const FrameRays& fr, int units, int threads, RayImage& img) const {
  const SensorConfig& sensor = config_.sensor;
  const std::size_t N =
      sensor.isRosette() ? static_cast<std::size_t>(units) : static_cast<std::size_t>(sensor.beams()) * sensor.columns;
  img.range.assign(N, -1.0f);
  img.intensity.assign(N, 0.0f);
  img.label.assign(N, 0);
  img.point.resize(N);
  auto cast = [&](int begin, int end) {
    if (sensor.isRosette())
      castRosette(fr, img, begin, end);
    else
      castSpinning(fr, img, begin, end);
  };
  threads = std::clamp(threads, 1, units);
  if (threads == 1) {
    cast(0, units);
    return;
  }
  std::vector<std::thread> pool;
  for (int k = 1; k < threads; ++k)
    pool.emplace_back(cast, static_cast<int>(static_cast<long>(units) * k / threads),
                      static_cast<int>(static_cast<long>(units) * (k + 1) / threads));
  cast(0, units / threads);
  for (auto& t : pool) t.join();
}

// Spinning sensor: columns [c_begin, c_end), every beam.
void Simulator::castSpinning(const FrameRays& fr, RayImage& img, int c_begin, int c_end) const {
  const int B = config_.sensor.beams();
  const bool offsets = !laser_el_.empty();
  for (int c = c_begin; c < c_end; ++c) {
    const RayOrigin& ro = fr.sweep.empty() ? fr.start : fr.sweep[c];
    for (int b = 0; b < B; ++b) {
      if (ego_blocked_[static_cast<std::size_t>(c) * B + b]) continue;
      const std::uint32_t ray =
          static_cast<std::uint32_t>(c) * static_cast<std::uint32_t>(B) + static_cast<std::uint32_t>(b);
      const Vec3f ds(cos_el_[b] * cos_az_[c], cos_el_[b] * sin_az_[c], sin_el_[b]);
      if (!offsets) {
        castOne(fr, ro, ray, ds, ds, 0.0f, static_cast<std::size_t>(c) * B + b, img);
        continue;
      }
      // The laser's true direction: its elevation and azimuth offsets added to the nominal angles.
      const float se = true_sin_el_[b], ce = true_cos_el_[b], ca = turn_cos_az_[b], sa = turn_sin_az_[b];
      const Vec3f dt(ce * (cos_az_[c] * ca - sin_az_[c] * sa), ce * (sin_az_[c] * ca + cos_az_[c] * sa), se);
      castOne(fr, ro, ray, ds, dt, laser_bias_[b], static_cast<std::size_t>(c) * B + b, img);
    }
  }
}

// Rosette: rays [k_begin, k_end) in firing order.
void Simulator::castRosette(const FrameRays& fr, RayImage& img, int k_begin, int k_end) const {
  const bool offsets = !laser_el_.empty();
  const float height = static_cast<float>(config_.world.sensor_height);
  for (int k = k_begin; k < k_end; ++k) {
    const RosetteRay& r = fr.rosette[k];
    const Vec3f ds(std::cos(r.elevation) * std::cos(r.azimuth), std::cos(r.elevation) * std::sin(r.azimuth),
                   std::sin(r.elevation));
    Vec3f dt = ds;
    float bias = 0.0f;
    if (offsets) {
      const float el = r.elevation + laser_el_[r.channel], az = r.azimuth + laser_az_[r.channel];
      dt = Vec3f(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
      bias = laser_bias_[r.channel];
    }
    const float d[3] = {dt.x(), dt.y(), dt.z()};
    if (config_.sensor.ego_vehicle && hitsEgoVehicle(d, height)) continue;
    castOne(fr, fr.sweep.empty() ? fr.start : fr.sweep[k], static_cast<std::uint32_t>(k), ds, dt, bias,
            static_cast<std::size_t>(k), img);
  }
}

// One ray: cast along the true direction dt, report along the nominal direction ds.
void Simulator::castOne(const FrameRays& fr, const RayOrigin& ro, std::uint32_t ray, const Vec3f& ds, const Vec3f& dt,
                        float bias, std::size_t px, RayImage& img) const {
  const std::uint64_t ray_key = mix64(fr.frame_key ^ (static_cast<std::uint64_t>(ray) << 20));
  const Vec3f d = ro.R * dt;
  Return ret;
  if (fr.sweep.empty()) {
    const RayHit hit = castRay<false>(fr.scene, ro, d, ray_key);
    if (!sensorReturn<false>(fr.scene, world_, config_.sensor, ro, d, hit, bias, ray_key, ret)) return;
  } else {
    const RayHit hit = castRay<true>(fr.scene, ro, d, ray_key);
    if (!sensorReturn<true>(fr.scene, world_, config_.sensor, ro, d, hit, bias, ray_key, ret)) return;
  }
  img.range[px] = ret.range;
  img.point[px] = ds * ret.range;
  img.label[px] = ret.label;
  img.intensity[px] = ret.intensity;
}

// The image's returns as the frame's points: spinning column by column (each column top beam first), rosette
// in firing order with its pseudo-image cell as beam / column.
void Simulator::compact(const FrameRays& fr, const RayImage& img, Frame& out) const {
  out.scan.points.clear();
  out.scan.labels.clear();
  out.intensity.clear();
  out.clean_labels.clear();
  out.beam.clear();
  out.column.clear();
  out.point_time.clear();
  std::size_t count = 0;
  for (float r : img.range) count += r > 0.0f;
  out.scan.points.reserve(count);
  out.scan.labels.reserve(count);
  out.intensity.reserve(count);
  out.beam.reserve(count);
  out.column.reserve(count);
  const int B = config_.sensor.beams();
  const bool timed = !fr.sweep.empty();
  if (timed) out.point_time.reserve(count);
  // A ray of column c (spinning) or ray k (rosette) fires at c / units of the sweep (render(): fr.sweep).
  const double per_unit = trajectory_.frame_dt / static_cast<double>(fr.sweep.size() ? fr.sweep.size() : 1);
  for (std::size_t px = 0; px < img.range.size(); ++px) {
    if (img.range[px] <= 0.0f) continue;
    if (timed) out.point_time.push_back(static_cast<float>(per_unit * (fr.rosette.empty() ? px / B : px)));
    out.scan.points.push_back(img.point[px]);
    out.scan.labels.push_back(img.label[px]);
    out.intensity.push_back(img.intensity[px]);
    if (fr.rosette.empty()) {
      out.beam.push_back(static_cast<std::uint16_t>(px % B));
      out.column.push_back(static_cast<std::uint16_t>(px / B));
    } else {
      out.beam.push_back(fr.rosette[px].row);
      out.column.push_back(fr.rosette[px].column);
    }
  }
}

}  // namespace sglc::sim
