// The procedural urban world around a trajectory: a road corridor along the driven path, roadside bands,
// buildings, fences, vegetation, trees, poles, signs, parked and moving vehicles, pedestrians.
// Everything is in world coordinates (z up; the world frame is the LiDAR frame of trajectory frame 0), and
// is a pure function of (seed, trajectory poses, WorldConfig): which frames are later rendered, and by how
// many threads, never changes it.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "sglc/types.hpp"

namespace sglc::sim {

// SemanticKITTI raw label ids the simulator emits.
namespace label {
inline constexpr std::uint32_t kUnlabelled = 0;
inline constexpr std::uint32_t kCar = 10;
inline constexpr std::uint32_t kTruck = 18;
inline constexpr std::uint32_t kOtherVehicle = 20;
inline constexpr std::uint32_t kPerson = 30;
inline constexpr std::uint32_t kRoad = 40;
inline constexpr std::uint32_t kParking = 44;
inline constexpr std::uint32_t kSidewalk = 48;
inline constexpr std::uint32_t kOtherGround = 49;
inline constexpr std::uint32_t kBuilding = 50;
inline constexpr std::uint32_t kFence = 51;
inline constexpr std::uint32_t kVegetation = 70;
inline constexpr std::uint32_t kTrunk = 71;
inline constexpr std::uint32_t kTerrain = 72;
inline constexpr std::uint32_t kPole = 80;
inline constexpr std::uint32_t kOtherObject = 99;
inline constexpr std::uint32_t kTrafficSign = 81;
inline constexpr std::uint32_t kMovingCar = 252;
inline constexpr std::uint32_t kMovingPerson = 254;
inline constexpr std::uint32_t kMovingTruck = 258;
inline constexpr std::uint32_t kMovingOtherVehicle = 259;

inline constexpr std::uint32_t classOf(std::uint32_t raw) { return raw & 0xFFFFu; }
inline constexpr std::uint32_t instanceOf(std::uint32_t raw) { return raw >> 16; }
// The static class of a moving one (252-259), as SemanticKITTI's single-scan benchmark folds them; any other
// class unchanged.
inline constexpr std::uint32_t staticOf(std::uint32_t cls) {
  switch (cls) {
    case kMovingCar:
      return kCar;
    case 253:
      return 31;  // moving-bicyclist -> bicyclist
    case kMovingPerson:
      return kPerson;
    case 255:
      return 32;  // moving-motorcyclist -> motorcyclist
    case 256:     // moving-on-rails
    case 257:     // moving-bus
    case kMovingOtherVehicle:
      return kOtherVehicle;
    case kMovingTruck:
      return kTruck;
    default:
      return cls;
  }
}
}  // namespace label

enum class Shape : std::uint8_t { kBox = 0, kCylinder = 1, kEllipsoid = 2 };

// Surface behaviour flags of a primitive.
enum PrimitiveFlag : std::uint8_t {
  kGlass = 1,    // vehicle windows: many returns are lost
  kWindows = 2,  // building facade with a window grid: returns inside windows are often lost
};

// One solid of the world. Boxes rotate about z, cylinders are vertical (side surface only, no caps),
// ellipsoids are axis-aligned.
struct Primitive {
  Shape shape = Shape::kBox;
  std::uint8_t flags = 0;
  std::uint8_t pass_through = 0;         // per ray, chance (x/255) that a ray passes a porous object (foliage, fences)
  float depth_jitter = 0.0f;             // foliage: the return comes from up to this deep inside the volume (m)
  std::uint32_t label = 0;               // SemanticKITTI raw id | instance << 16
  float reflectivity = 0.3f;             // 0..1, scales the intensity channel
  double cx = 0.0, cy = 0.0;             // centre in the world (m)
  float z0 = 0.0f, z1 = 0.0f;            // vertical extent (world z)
  float hx = 0.0f, hy = 0.0f;            // box half length (along its axis) / half width; cylinder radius (hx);
                                         // ellipsoid horizontal semi-axes
  float cos_yaw = 1.0f, sin_yaw = 0.0f;  // box axis direction in the world
  float radius = 0.0f;                   // bounding circle in xy (m)
  std::uint32_t presence = 0;            // 0: always there; else when it is there (World::present)
};

struct WorldConfig {
  double sensor_height = 1.73;   // LiDAR above the ground under the vehicle (m)
  bool moving_objects = true;    // moving vehicles on the road and pedestrians on sidewalks
  double path_extension = 60.0;  // the street continues this far beyond both ends of the trajectory (m)
  // Time (tools/sim/README.md, "Time and look-alike streets"). Off: the world is frozen as it is today. On:
  // parked vehicles come and go, temporary objects (skips, construction fences, trucks) appear and vanish,
  // and foliage follows the season; a frame at time t (s) shows the world at epoch * 86400 s + t.
  bool turnover = false;
  int epoch = 0;  // days after today (>= 0); used only with turnover
  // Share of lots (0..1) whose content (length, buildings, yard, fence, bays) is copied from one of a few
  // templates per district type instead of being drawn from its own position: look-alike streets.
  double aliasing = 0.0;
};

// Street cross-section, drawn once from the seed (lateral distances from the driven path, m).
struct WorldStyle {
  double lane_width = 3.3;
  double road_half_width = 4.5;  // road (40) within this distance of the path
  double parking_width = 2.3;    // then a parking strip (44, or road where a district has no parking)
  double sidewalk_width = 2.5;   // then the sidewalk (48); beyond it, lots (buildings, yards, parks)
  double kerb() const { return road_half_width + parking_width; }
  double lotLine() const { return road_half_width + parking_width + sidewalk_width; }
};

enum class District : std::uint8_t { kUrban = 0, kResidential = 1, kGreen = 2, kIndustrial = 3 };
const char* districtName(District d);

// The ground rasters around one sensor position, copied into flat arrays so that the many per-ray
// lookups of a frame avoid the world's tiled storage. Values equal the world's rasters.
struct GroundPatch {
  double hx0 = 0, hy0 = 0, hcell = 4;  // height samples at (hx0 + (i + 0.5) hcell, hy0 + (j + 0.5) hcell)
  int hnx = 0, hny = 0;
  std::vector<float> h;
  double dx0 = 0, dy0 = 0, dcell = 1;  // band distance samples, same layout
  int dnx = 0, dny = 0;
  std::vector<float> d;

  double hinv = 0.25, dinv = 1.0;  // 1 / cell

  double height(double x, double y) const {
    return sample(h, hnx, hny, (x - hx0) * hinv - 0.5, (y - hy0) * hinv - 0.5);
  }
  double distance(double x, double y) const {
    return sample(d, dnx, dny, (x - dx0) * dinv - 0.5, (y - dy0) * dinv - 0.5);
  }

 private:
  static double sample(const std::vector<float>& v, int nx, int ny, double fx, double fy) {
    fx = fx < 0 ? 0 : (fx > nx - 1.001 ? nx - 1.001 : fx);
    fy = fy < 0 ? 0 : (fy > ny - 1.001 ? ny - 1.001 : fy);
    const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
    const double ax = fx - ix, ay = fy - iy;
    const float* r0 = v.data() + static_cast<std::size_t>(iy) * nx + ix;
    const float* r1 = r0 + nx;
    return (1 - ay) * ((1 - ax) * r0[0] + ax * r0[1]) + ay * ((1 - ax) * r1[0] + ax * r1[1]);
  }
};

struct WorldStats {
  std::size_t primitives = 0;
  std::size_t buildings = 0, fences = 0, hedges = 0, trees = 0, bushes = 0, poles = 0, signs = 0;
  std::size_t parked_vehicles = 0, moving_agents = 0;
  std::size_t parking_slots = 0, temporary_sites = 0, aliased_lots = 0;  // with turnover / aliasing only
  double path_length_m = 0.0;
  std::size_t memory_bytes = 0;  // world model (rasters, primitives, indices)
  double build_seconds = 0.0;
};

class World {
 public:
  // poses: LiDAR poses (LiDAR -> world) of the whole trajectory.
  World(const std::vector<Mat4d>& poses, std::uint64_t seed, const WorldConfig& config = {});
  ~World();
  World(World&&) noexcept;
  World& operator=(World&&) noexcept;
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  std::uint64_t seed() const;
  const WorldConfig& config() const;
  const WorldStyle& style() const;
  const WorldStats& stats() const;

  // Static primitives; the index is the primitive's stable id.
  const std::vector<Primitive>& statics() const;
  // Ids of static primitives whose bounding circle may lie within `radius` of (x, y), ascending.
  void staticsNear(double x, double y, double radius, std::vector<int>& ids) const;
  // Whether a static primitive is there at absolute time `time` (s, see absoluteTime): parked vehicles and
  // temporary objects of a world with turnover come and go; everything else is always there.
  bool present(const Primitive& p, double time) const;
  // The absolute time of a frame at `frame_time` seconds into the trajectory: epoch * 86400 + frame_time.
  double absoluteTime(double frame_time) const;
  // Moving agents (vehicles, pedestrians) at `time` seconds, whose centre lies within `radius` of (x, y).
  // Positions are a function of time only.
  void movingNear(double time, double x, double y, double radius, std::vector<Primitive>& out) const;

  // Ground surface: smooth height following the trajectory, and its SemanticKITTI class at (x, y).
  double groundHeight(double x, double y) const;
  std::uint32_t groundLabel(double x, double y) const;
  // Distance (m) to the driven path as used for the street bands, clamped at 24 m.
  double roadDistance(double x, double y) const;
  // Class of the ground at (x, y) given its band distance (as groundLabel, without the raster lookup).
  std::uint32_t groundLabelAt(double x, double y, double road_distance) const;
  // Copies the ground rasters within `radius` of (x, y) (clamped to the edge beyond it).
  void groundPatch(double x, double y, double radius, GroundPatch& patch) const;
  District district(double x, double y) const;

  // Order-sensitive hash of all static content and the moving agents (for determinism checks).
  std::uint64_t contentHash() const;

  struct Impl;  // opaque (world.cpp)

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace sglc::sim
