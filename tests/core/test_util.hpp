// Shared helpers for the core tests: synthetic scans, rigid transforms, temp dirs and the real-data path.
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>
#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <numbers>
#include <random>
#include <string>
#include <system_error>
#include <vector>

#include "sglc/types.hpp"

namespace sglc::test {

// SemanticKITTI raw ids used by the default label map.
inline constexpr std::uint32_t kCar = 10;
inline constexpr std::uint32_t kRoad = 40;
inline constexpr std::uint32_t kBuilding = 50;
inline constexpr std::uint32_t kFence = 51;
inline constexpr std::uint32_t kVegetation = 70;
inline constexpr std::uint32_t kTrunk = 71;
inline constexpr std::uint32_t kPole = 80;
inline constexpr std::uint32_t kUnlabelled = 0;

inline double deg2rad(double d) { return d * std::numbers::pi / 180.0; }
inline double rad2deg(double r) { return r * 180.0 / std::numbers::pi; }

// Rigid transform: rotation yaw (about z), then pitch (about y), then roll (about x), plus a translation.
inline Mat4d makeT(double yaw_deg, double tx, double ty, double tz, double pitch_deg = 0.0, double roll_deg = 0.0) {
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() =
      (Eigen::AngleAxisd(deg2rad(yaw_deg), Vec3d::UnitZ()) * Eigen::AngleAxisd(deg2rad(pitch_deg), Vec3d::UnitY()) *
       Eigen::AngleAxisd(deg2rad(roll_deg), Vec3d::UnitX()))
          .toRotationMatrix();
  T.topRightCorner<3, 1>() = Vec3d(tx, ty, tz);
  return T;
}

inline Vec3d apply(const Mat4d& T, const Vec3d& p) { return T.topLeftCorner<3, 3>() * p + T.topRightCorner<3, 1>(); }
inline Vec3f apply(const Mat4d& T, const Vec3f& p) { return apply(T, Vec3d(p.cast<double>())).cast<float>(); }

inline Points transformPoints(const Mat4d& T, const Points& pts) {
  Points out;
  out.reserve(pts.size());
  for (const auto& p : pts) out.push_back(apply(T, p));
  return out;
}

inline double translationError(const Mat4d& A, const Mat4d& B) {
  return (A.topRightCorner<3, 1>() - B.topRightCorner<3, 1>()).norm();
}

// Angle (deg) of the relative rotation A^T B.
inline double rotationErrorDeg(const Mat4d& A, const Mat4d& B) {
  const Mat3d R = A.topLeftCorner<3, 3>().transpose() * B.topLeftCorner<3, 3>();
  return rad2deg(std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0)));
}

// Appends n points of one label.
inline void addPoints(LabelledScan& scan, const Points& pts, std::uint32_t label) {
  for (const auto& p : pts) {
    scan.points.push_back(p);
    scan.labels.push_back(label);
  }
}

// A vertical pole: a ring of `per_ring` points of radius r every dz metres from z0 to z1, the first point of
// each ring at angle `phase` (rad) around the pole axis.
inline Points makePole(double x, double y, double z0, double z1, double r = 0.15, int per_ring = 8, double dz = 0.1,
                       double phase = 0.0) {
  Points pts;
  for (double z = z0; z <= z1 + 1e-9; z += dz)
    for (int k = 0; k < per_ring; ++k) {
      const double a = phase + 2.0 * std::numbers::pi * k / per_ring;
      pts.emplace_back(static_cast<float>(x + r * std::cos(a)), static_cast<float>(y + r * std::sin(a)),
                       static_cast<float>(z));
    }
  return pts;
}

// The surface of an axis-aligned box (centre c, half sizes h) rotated by yaw about its centre, sampled on a grid.
inline Points makeBoxSurface(const Vec3d& c, const Vec3d& h, double yaw_deg, double step) {
  Points pts;
  const Mat3d R = Eigen::AngleAxisd(deg2rad(yaw_deg), Vec3d::UnitZ()).toRotationMatrix();
  auto emit = [&](const Vec3d& local) { pts.push_back((c + R * local).cast<float>()); };
  const int nx = std::max(1, static_cast<int>(std::round(2 * h.x() / step)));
  const int ny = std::max(1, static_cast<int>(std::round(2 * h.y() / step)));
  const int nz = std::max(1, static_cast<int>(std::round(2 * h.z() / step)));
  for (int i = 0; i <= nx; ++i)
    for (int j = 0; j <= ny; ++j) {
      const double x = -h.x() + 2 * h.x() * i / nx, y = -h.y() + 2 * h.y() * j / ny;
      emit({x, y, -h.z()});
      emit({x, y, h.z()});
    }
  for (int i = 0; i <= nx; ++i)
    for (int k = 1; k < nz; ++k) {
      const double x = -h.x() + 2 * h.x() * i / nx, z = -h.z() + 2 * h.z() * k / nz;
      emit({x, -h.y(), z});
      emit({x, h.y(), z});
    }
  for (int j = 1; j < ny; ++j)
    for (int k = 1; k < nz; ++k) {
      const double y = -h.y() + 2 * h.y() * j / ny, z = -h.z() + 2 * h.z() * k / nz;
      emit({-h.x(), y, z});
      emit({h.x(), y, z});
    }
  return pts;
}

// A flat horizontal patch [x0, x1] x [y0, y1] at height z, sampled every `step` metres.
inline Points makeFloor(double x0, double x1, double y0, double y1, double z, double step) {
  Points pts;
  for (double x = x0; x <= x1 + 1e-9; x += step)
    for (double y = y0; y <= y1 + 1e-9; y += step)
      pts.emplace_back(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
  return pts;
}

// A vertical wall from (x0, y0) to (x1, y1), z in [z0, z1], sampled every `step` metres.
inline Points makeWall(double x0, double y0, double x1, double y1, double z0, double z1, double step) {
  Points pts;
  const double len = std::hypot(x1 - x0, y1 - y0);
  const int n = std::max(1, static_cast<int>(std::round(len / step)));
  for (int i = 0; i <= n; ++i) {
    const double s = static_cast<double>(i) / n;
    for (double z = z0; z <= z1 + 1e-9; z += step)
      pts.emplace_back(static_cast<float>(x0 + s * (x1 - x0)), static_cast<float>(y0 + s * (y1 - y0)),
                       static_cast<float>(z));
  }
  return pts;
}

// A synthetic "street" in world coordinates: road, two building facades, fences, vegetation and an irregular set
// of poles, trunks and cars. Deterministic (fixed seed). Used to produce two views of the same place.
inline LabelledScan makeStreetWorld(std::uint32_t seed = 7) {
  LabelledScan w;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  addPoints(w, makeFloor(-40, 40, -7, 7, -1.7, 0.4), kRoad);
  addPoints(w, makeWall(-40, 9, 40, 9, -1.7, 6, 0.4), kBuilding);
  addPoints(w, makeWall(-40, -12, 40, -12, -1.7, 6, 0.4), kBuilding);
  addPoints(w, makeWall(-30, -9, -5, -9, -1.7, -0.5, 0.3), kFence);
  addPoints(w, makeFloor(5, 35, -11, -8, -1.0, 0.5), kVegetation);
  // Landmarks at irregular positions (irregular so that no two local neighbourhoods are congruent).
  for (int k = 0; k < 14; ++k) {
    const double x = -36 + k * 5.3 + 1.2 * u(rng);
    const double y = (k % 2 ? 7.6 : -7.8) + 0.3 * u(rng);
    addPoints(w, makePole(x, y, -1.7, 3.5 + u(rng)), k % 3 == 0 ? kTrunk : kPole);
  }
  for (int k = 0; k < 5; ++k) {
    const double x = -30 + k * 13.7 + 2.0 * u(rng);
    const double y = (k % 2 ? 5.2 : -5.0) + 0.3 * u(rng);
    addPoints(w, makeBoxSurface({x, y, -1.0}, {2.1 + 0.3 * u(rng), 0.9, 0.7}, 3.0 * u(rng), 0.1), kCar);
  }
  return w;
}

// The world seen from a sensor at pose T_world_sensor: every world point within `range` in sensor coordinates.
inline LabelledScan viewFrom(const LabelledScan& world, const Mat4d& T_world_sensor, double range = 80.0) {
  const Mat4d T_sensor_world = T_world_sensor.inverse();
  LabelledScan s;
  for (std::size_t i = 0; i < world.points.size(); ++i) {
    const Vec3f p = apply(T_sensor_world, world.points[i]);
    if (p.head<2>().norm() > range) continue;
    s.points.push_back(p);
    s.labels.push_back(world.labels[i]);
  }
  return s;
}

// A fresh temporary directory, removed with everything in it when the object goes out of scope.
class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = "sglc_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
    if (info) name += std::string("_") + info->name();
    path_ = std::filesystem::temp_directory_path() / name;
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// ../shared/data/semantickitti_scans, or "" when absent.
inline std::string scansDir() {
  const std::filesystem::path dir = std::filesystem::path(SGLC_SHARED_DATA) / "semantickitti_scans";
  return std::filesystem::is_directory(dir) ? dir.string() : std::string();
}

#define SGLC_REQUIRE_REAL_DATA()                                                                             \
  do {                                                                                                       \
    if (::sglc::test::scansDir().empty())                                                                    \
      GTEST_SKIP() << "real data not found: " << SGLC_SHARED_DATA                                            \
                   << "/semantickitti_scans is absent (SemanticKITTI scans are not part of the repository)"; \
  } while (0)

}  // namespace sglc::test
