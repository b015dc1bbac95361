// Sensor realism: named presets, the rosette scanner, per-laser offsets, mixed pixels, motion distortion.
#include "sglc/deskew.hpp"
#include "sim/sensor.hpp"
#include "sim_test_util.hpp"

namespace sglc::sim::test {
namespace {

bool sameFrame(const Frame& a, const Frame& b) {
  return a.scan.points == b.scan.points && a.scan.labels == b.scan.labels && a.intensity == b.intensity &&
         a.beam == b.beam && a.column == b.column;
}

// Points by (beam, column) cell, for comparing two renders of the same spinning sensor.
std::map<std::pair<int, int>, std::size_t> cells(const Frame& f) {
  std::map<std::pair<int, int>, std::size_t> m;
  for (std::size_t i = 0; i < f.beam.size(); ++i) m[{f.beam[i], f.column[i]}] = i;
  return m;
}

double median(std::vector<double> v) {
  if (v.empty()) return -1.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

TEST(Sensor, NamedPresetsHaveTheirLayouts) {
  struct Want {
    const char* name;
    int beams, columns;
    double top, bottom, range;
  };
  for (const Want& w : {Want{"vlp16", 16, 1800, 15.0, -15.0, 100.0}, Want{"hdl32", 32, 1800, 10.67, -30.67, 100.0},
                        Want{"hdl64", 64, 2083, 2.0, -24.8, 80.0}, Want{"os1-128", 128, 1024, 22.5, -22.5, 120.0}}) {
    SCOPED_TRACE(w.name);
    const SensorConfig s = sensorPreset(w.name);
    EXPECT_EQ(s.name, w.name);
    EXPECT_EQ(s.beams(), w.beams);
    EXPECT_EQ(s.columns, w.columns);
    EXPECT_NEAR(s.elevation_deg.front(), w.top, 1e-9);
    EXPECT_NEAR(s.elevation_deg.back(), w.bottom, 1e-9);
    EXPECT_EQ(s.max_range, w.range);
    EXPECT_FALSE(s.isRosette());
    EXPECT_FALSE(s.laser_offsets);
    EXPECT_EQ(s.mixed_pixel_rate, 0.0);
    EXPECT_FALSE(s.motion_distortion);
  }
  EXPECT_EQ(sensorPreset("hdl64").elevation_deg, SimConfig{}.sensor.elevation_deg);  // the default
  const SensorConfig r = sensorPreset("rosette");
  EXPECT_TRUE(r.isRosette());
  EXPECT_EQ(r.rosette_rays, 24000);
  EXPECT_NEAR(r.rosette_fov_h_deg, 70.4, 1e-9);
  EXPECT_NEAR(r.rosette_fov_v_deg, 77.2, 1e-9);
  EXPECT_EQ(r.max_range, 150.0);
  EXPECT_THROW(sensorPreset("hdl16"), InputError);
}

TEST(Sensor, RosetteRaysStayInTheFieldOfViewAndNeverRepeat) {
  const SensorConfig s = SensorConfig::rosette();
  std::vector<RosetteRay> a, b, a2;
  rosetteRays(s, 7, 10, a);
  rosetteRays(s, 7, 11, b);
  rosetteRays(s, 7, 10, a2);
  ASSERT_EQ(a.size(), 24000u);
  const double half_h = 0.5 * 70.4 * std::numbers::pi / 180, half_v = 0.5 * 77.2 * std::numbers::pi / 180;
  double max_h = 0, max_v = 0;
  std::set<std::pair<int, int>> cells_hit;
  for (const auto& r : a) {
    max_h = std::max(max_h, std::abs(static_cast<double>(r.azimuth)));
    max_v = std::max(max_v, std::abs(static_cast<double>(r.elevation)));
    ASSERT_LT(r.row, s.beams());
    ASSERT_LT(r.column, s.columns);
    cells_hit.insert({r.row, r.column});
  }
  EXPECT_LE(max_h, half_h + 1e-6);
  EXPECT_LE(max_v, half_v + 1e-6);
  EXPECT_GT(max_h, 0.95 * half_h);  // the pattern reaches the edges of its field of view
  EXPECT_GT(max_v, 0.95 * half_v);
  EXPECT_GT(cells_hit.size(), 3000u);  // and spreads over it
  int same = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    same += a[k].azimuth == b[k].azimuth && a[k].elevation == b[k].elevation;
    ASSERT_EQ(a[k].azimuth, a2[k].azimuth);
  }
  EXPECT_LT(same, 10);
}

TEST(Sensor, RosetteFramesLookForwardAndAreDeterministic) {
  SimConfig cfg;
  cfg.sensor = SensorConfig::rosette();
  const Simulator sim(loopTrajectory(), cfg);
  const Frame f = sim.render(100), g = sim.render(101);
  Frame again;
  sim.render(100, again, 3);
  EXPECT_TRUE(sameFrame(f, again));
  ASSERT_GT(f.scan.points.size(), 8000u);
  EXPECT_LE(f.scan.points.size(), 24000u);
  for (std::size_t i = 0; i < f.scan.points.size(); ++i) {
    const Vec3f& p = f.scan.points[i];
    ASSERT_GT(p.x(), 0.0f);  // forward-looking
    ASSERT_LE(std::abs(std::atan2(p.y(), p.x())), 0.5 * 70.4 * std::numbers::pi / 180 + 1e-3);
    ASSERT_LT(f.beam[i], 128);
    ASSERT_LT(f.column[i], 128);
  }
  EXPECT_NE(f.scan.points.size(), g.scan.points.size());
}

TEST(Sensor, LaserOffsetsAreOffByDefaultAndSmall) {
  SimConfig cfg = smallConfig(7);
  cfg.sensor.columns = 1024;
  cfg.sensor.noiseFree();
  const Simulator plain(loopTrajectory(), cfg);
  cfg.sensor.laser_offsets = true;
  const Simulator offset(loopTrajectory(), cfg);
  const Frame a = plain.render(400), b = offset.render(400);
  const auto cb = cells(b);
  std::vector<double> moved;
  for (std::size_t i = 0; i < a.beam.size(); ++i) {
    auto it = cb.find({a.beam[i], a.column[i]});
    if (it != cb.end()) moved.push_back((a.scan.points[i] - b.scan.points[it->second]).norm());
  }
  ASSERT_GT(moved.size(), a.beam.size() * 9 / 10);
  // 0.05 deg / 0.1 deg / 1.5 cm sigmas: centimetres on most points, more on grazing ground.
  EXPECT_GT(median(moved), 0.005);
  EXPECT_LT(median(moved), 0.15);
  // The draws have the documented sigmas (64 lasers, so within about 30 %).
  const LaserOffsets o = laserOffsets(64, 7);
  auto rms = [](const std::vector<float>& v) {
    double s = 0;
    for (float x : v) s += x * x;
    return std::sqrt(s / v.size());
  };
  EXPECT_NEAR(rms(o.range_bias_m), kLaserRangeSigmaM, 0.3 * kLaserRangeSigmaM);
  EXPECT_NEAR(rms(o.azimuth_rad) * 180 / std::numbers::pi, kLaserAzimuthSigmaDeg, 0.3 * kLaserAzimuthSigmaDeg);
  EXPECT_NEAR(rms(o.elevation_rad) * 180 / std::numbers::pi, kLaserElevationSigmaDeg, 0.3 * kLaserElevationSigmaDeg);
  EXPECT_NE(laserOffsets(64, 8).range_bias_m, o.range_bias_m);  // another unit, other errors
}

TEST(Sensor, MixedPixelsOnlyAtDepthEdgesWithTheForegroundLabel) {
  SimConfig cfg = smallConfig(7);
  cfg.sensor.columns = 1024;
  cfg.sensor.noiseFree();
  const Simulator plain(loopTrajectory(), cfg);
  cfg.sensor.mixed_pixel_rate = 0.5;
  const Simulator mixed(loopTrajectory(), cfg);
  std::size_t points = 0, mixed_points = 0;
  for (int index : {200, 900}) {
    const Frame a = plain.render(index), b = mixed.render(index);
    EXPECT_EQ(a.mixed_points, 0u);
    ASSERT_EQ(a.beam, b.beam);  // mixing moves points, never adds or drops them
    const auto ca = cells(a);
    const int C = cfg.sensor.columns;
    std::size_t changed = 0;
    for (std::size_t i = 0; i < a.beam.size(); ++i) {
      if (a.scan.points[i] == b.scan.points[i]) continue;
      ++changed;
      const float r = a.scan.points[i].norm(), rb = b.scan.points[i].norm();
      // A neighbour on the same beam lies more than 1 m nearer or farther, and the new range is in between; the
      // mix is with the neighbour across the larger step, and takes its label when that one is nearer.
      bool edge = false;
      float step = 1.0f;
      std::size_t other = a.beam.size();
      for (int dc : {-1, 1}) {
        auto it = ca.find({a.beam[i], (a.column[i] + dc + C) % C});
        if (it == ca.end()) continue;
        const float rn = a.scan.points[it->second].norm();
        if (std::abs(rn - r) > step) {
          step = std::abs(rn - r);
          other = it->second;
        }
      }
      if (other < a.beam.size()) {
        const float rn = a.scan.points[other].norm();
        edge = rb >= std::min(r, rn) - 1e-3f && rb <= std::max(r, rn) + 1e-3f;
        EXPECT_EQ(b.scan.labels[i], rn < r ? a.scan.labels[other] : a.scan.labels[i]);
      }
      EXPECT_TRUE(edge) << "beam " << a.beam[i] << " column " << a.column[i];
    }
    EXPECT_EQ(changed, b.mixed_points);
    points += b.scan.points.size();
    mixed_points += b.mixed_points;
  }
  const double share = static_cast<double>(mixed_points) / points;
  std::printf("mixed share at rate 0.5: %.4f\n", share);
  EXPECT_GT(share, 0.005);
  EXPECT_LT(share, 0.08);
}

TEST(Sensor, MotionDistortionIsIdentityWhenStill) {
  Trajectory still;
  Mat4d P = Mat4d::Identity();
  P(0, 3) = 5.0;
  still.poses.assign(40, P);
  SimConfig cfg = smallConfig(7);
  const Simulator a(still, cfg);
  cfg.sensor.motion_distortion = true;
  const Simulator b(still, cfg);
  EXPECT_TRUE(sameFrame(a.render(39), b.render(39)));
  EXPECT_TRUE(sameFrame(a.render(10), b.render(10)));
}

// At speed v the last column is cast v * frame_dt further on; its points, placed with the pose of their own time,
// land on the surfaces the undistorted scan sees, and placed with the frame's pose they are off by about that.
// Frame 150 of the built-in route (2048 columns, no noise), rendered still and with motion distortion.
struct DistortedFrame {
  static SimConfig config(bool distorted) {
    SimConfig cfg = smallConfig(7);
    cfg.sensor.columns = 2048;
    cfg.sensor.noiseFree();
    cfg.sensor.motion_distortion = distorted;
    return cfg;
  }
  const Trajectory& traj = loopTrajectory();
  const int index = 150;
  const SimConfig cfg = config(true);
  const Simulator plain{traj, config(false)};
  const Simulator moving{traj, config(true)};
};

TEST(Sensor, MotionDistortionCastsTheLastColumnFromTheMovedSensor) {
  const DistortedFrame d;
  // Named one by one (not a structured binding): the lambdas below capture them.
  const Trajectory& traj = d.traj;
  const int index = d.index;
  const SimConfig& cfg = d.cfg;
  const Simulator& plain = d.plain;
  const Simulator& moving = d.moving;
  const auto& poses = plain.trajectory().poses;
  const double v = translationError(poses[index], poses[index + 1]) / traj.frame_dt;
  ASSERT_GT(v, 5.0);
  const SweepMotion sweep(poses, index);
  EXPECT_NEAR(translationError(sweep.at(1.0), poses[index]), v * traj.frame_dt, 0.05 * v * traj.frame_dt);
  const Frame a = plain.render(index), b = moving.render(index);
  const int C = cfg.sensor.columns;
  // Undistorted world points of the near-horizontal beams (0: +2 deg, 1: +0.2 deg) by beam.
  std::map<int, std::vector<Vec3d>> world_a;
  for (std::size_t i = 0; i < a.beam.size(); ++i)
    if (a.beam[i] <= 1)
      world_a[a.beam[i]].push_back((poses[index] * a.scan.points[i].cast<double>().homogeneous()).head<3>());
  std::vector<double> own_time, frame_pose, shift;
  for (std::size_t i = 0; i < b.beam.size(); ++i) {
    if (b.beam[i] > 1 || b.column[i] < C - 40) continue;
    const Vec3d p = b.scan.points[i].cast<double>();
    const Vec3d at_own = (sweep.at(static_cast<double>(b.column[i]) / C) * p.homogeneous()).head<3>();
    const Vec3d at_frame = (poses[index] * p.homogeneous()).head<3>();
    auto nearest = [&](const Vec3d& q) {
      double best = 1e9;
      for (const Vec3d& w : world_a[b.beam[i]]) best = std::min(best, (w - q).norm());
      return best;
    };
    own_time.push_back(nearest(at_own));
    frame_pose.push_back(nearest(at_frame));
    shift.push_back((at_own - at_frame).norm());
  }
  ASSERT_GT(own_time.size(), 20u);
  std::printf("v %.2f m/s; last columns: nearest undistorted point %.3f m (own-time pose), %.3f m (frame pose)\n", v,
              median(own_time), median(frame_pose));
  EXPECT_NEAR(median(shift), v * traj.frame_dt, 0.1 * v * traj.frame_dt);
  EXPECT_LT(median(own_time), 0.1);
  EXPECT_GT(median(frame_pose), 3 * median(own_time));
}

// The times the simulator gives each point (when its column fired) are what de-skew needs: with the twist of the
// frame's motion (the poses around it), the distorted points land on the undistorted scan's surfaces.
TEST(Sensor, MotionDistortionGivesPointTimesThatDeskewTheSweep) {
  const DistortedFrame d;
  // Named one by one (not a structured binding): the lambdas below capture them.
  const Trajectory& traj = d.traj;
  const int index = d.index;
  const SimConfig& cfg = d.cfg;
  const Simulator& plain = d.plain;
  const Simulator& moving = d.moving;
  EXPECT_TRUE(plain.render(index).point_time.empty());
  const auto& poses = plain.trajectory().poses;
  const Frame a = plain.render(index), b = moving.render(index);
  const int C = cfg.sensor.columns;
  ASSERT_EQ(b.point_time.size(), b.scan.points.size());
  for (std::size_t i = 0; i < b.point_time.size(); i += 97)
    EXPECT_FLOAT_EQ(b.point_time[i], static_cast<float>(traj.frame_dt * b.column[i] / C));
  Points fixed = b.scan.points;
  deskew(fixed, b.point_time, twistBetween(poses[index], poses[index + 1], traj.frame_dt));
  std::map<int, std::vector<Vec3d>> world_a;
  for (std::size_t i = 0; i < a.beam.size(); ++i)
    if (a.beam[i] <= 1)
      world_a[a.beam[i]].push_back((poses[index] * a.scan.points[i].cast<double>().homogeneous()).head<3>());
  std::vector<double> deskewed, raw;
  for (std::size_t i = 0; i < b.beam.size(); ++i) {
    if (b.beam[i] > 1 || b.column[i] < C - 40) continue;
    auto nearest = [&](const Vec3f& p) {
      const Vec3d q = (poses[index] * p.cast<double>().homogeneous()).head<3>();
      double best = 1e9;
      for (const Vec3d& w : world_a[b.beam[i]]) best = std::min(best, (w - q).norm());
      return best;
    };
    deskewed.push_back(nearest(fixed[i]));
    raw.push_back(nearest(b.scan.points[i]));
  }
  ASSERT_GT(deskewed.size(), 20u);
  EXPECT_LT(median(deskewed), 0.1);
  EXPECT_GT(median(raw), 3 * median(deskewed));
}

}  // namespace
}  // namespace sglc::sim::test
