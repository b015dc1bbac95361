// Labelled spinning-LiDAR simulator: trajectories, sensor presets, label noise, and per-frame rendering.
//
//   auto traj = sglc::sim::loadKittiTrajectory("00.txt", "calib.txt");
//   sglc::sim::Simulator sim(traj, {.seed = 7});
//   sglc::sim::Frame f = sim.render(52);   // f.scan: sensor-frame points + SemanticKITTI labels
//
// A frame is a pure function of (seed, trajectory, configuration, frame index): rendering frames in any
// order, subset, or thread count gives the same bytes.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "sglc/types.hpp"
#include "sim/world.hpp"

namespace sglc::sim {

// ---- Trajectory ---------------------------------------------------------------------------------------

struct Trajectory {
  std::vector<Mat4d> poses;      // LiDAR -> world; the world is the LiDAR frame of frame 0
  double frame_dt = 0.1;         // seconds between consecutive frames (KITTI: 10 Hz)
  Mat4d Tr = Mat4d::Identity();  // velodyne -> cam0 calibration the poses were converted with
  std::string source;            // human-readable origin
};

// KITTI camera (cam0) poses -> LiDAR poses: T_lidar_i = inv(Tr) * P_i * Tr.
Trajectory kittiTrajectory(const std::vector<Mat4d>& camera_poses, const Mat4d& Tr, std::string source = "");
// Reads a KITTI poses file and the Tr line of a calib.txt. Throws InputError.
Trajectory loadKittiTrajectory(const std::string& poses_path, const std::string& calib_path);
// The built-in route: a 200 m x 120 m city block driven once counter-clockwise, then half of it again
// (same-direction revisits), a detour round a second block, and back along the first block's streets the
// other way (reverse revisits), with intersections and gentle slopes. About 1900 frames at 10 Hz.
Trajectory loopRoute();

// ---- Sensor -------------------------------------------------------------------------------------------

struct SensorConfig {
  std::string name = "hdl64";
  std::vector<double> elevation_deg;  // one per beam, top to bottom
  int columns = 2083;                 // azimuth steps per revolution
  double max_range = 80.0;            // m
  double min_range = 1.0;             // m
  double range_noise = 0.02;          // Gaussian sigma (m)
  double dropout = 0.01;              // base chance that a return is lost
  double far_dropout = 0.15;          // extra loss at max range, growing with (range / max_range)^2
  double grazing_dropout = 0.5;       // extra loss at grazing incidence (cos < 0.2), fading in linearly
  double glass_dropout = 0.5;         // loss on vehicle windows and facade windows
  bool intensity_noise = true;
  // The ego vehicle's rear (a box 0.85 m above ground from 0.5 to 2.7 m behind the sensor, 1.8 m wide) hides
  // the ground straight behind, as in KITTI scans: rays hitting it give no return.
  bool ego_vehicle = true;
  // Non-repetitive rosette scanner (Livox-Avia-like) when rosette_rays > 0: that many rays per frame follow a
  // rose curve over a forward field of view of rosette_fov_h_deg x rosette_fov_v_deg. Points are then binned
  // into a pseudo range image of beams() rows (elevation_deg: row centres) x columns over that field of view.
  int rosette_rays = 0;
  double rosette_fov_h_deg = 70.4, rosette_fov_v_deg = 77.2;
  int rosette_channels = 6;  // lasers (for laser_offsets): ray k belongs to channel k % rosette_channels
  // Realism knobs, all off by default (sensor.hpp and tools/sim/README.md give the numbers):
  bool laser_offsets = false;      // per-laser elevation / azimuth / range calibration errors, seeded
  double mixed_pixel_rate = 0.0;   // chance that a return beside a > 1 m depth edge blends the two ranges
  bool motion_distortion = false;  // each ray cast from the pose at its own time in the sweep (not de-skewed)

  // Velodyne HDL-64E-like: 64 beams over +2 .. -24.8 deg (upper block of 32 at 1/3 deg, lower 32 at
  // ~1/2 deg), 2083 columns (0.173 deg), 80 m.
  static SensorConfig hdl64();
  // HDL-32E-like: 32 beams over +10.67 .. -30.67 deg, 1800 columns, 100 m.
  static SensorConfig hdl32();
  // 128 beams over +15 .. -25 deg, 1800 columns, 120 m.
  static SensorConfig beams128();
  // 32, 64 and 128 give the presets above; other counts spread uniformly over the HDL-64's +2 .. -24.8 deg.
  static SensorConfig preset(int beams);
  // Velodyne VLP-16-like: 16 beams +15 .. -15 deg, 1800 columns (0.2 deg), 100 m.
  static SensorConfig vlp16();
  // Ouster OS1-128-like: 128 beams +22.5 .. -22.5 deg, 1024 columns, 120 m.
  static SensorConfig os1_128();
  // Livox-Avia-like rosette: 24000 rays per 100 ms frame over 70.4 x 77.2 deg, 150 m, 128 x 128 pseudo image.
  static SensorConfig rosette();
  bool isRosette() const { return rosette_rays > 0; }
  int beams() const { return static_cast<int>(elevation_deg.size()); }
  // No range noise, no dropouts, no intensity noise.
  SensorConfig& noiseFree();
};

// ---- Label noise --------------------------------------------------------------------------------------

// Which label noise model applies: the three independent knobs below (kIid), or the network preset (kNetwork)
// calibrated to RangeNet53++'s published per-class IoU on SemanticKITTI (label_noise_network.hpp).
enum class LabelNoiseModel : std::uint8_t { kIid = 0, kNetwork = 1 };

// Mimics a segmentation network's output. All zero (iid model) = ground-truth labels.
struct LabelNoise {
  LabelNoiseModel model = LabelNoiseModel::kIid;
  // iid model only:
  double confusion = 0.0;  // chance that a point takes a plausible wrong class (car <-> truck, road <-> parking ...)
  double bleed = 0.0;      // chance that a point at a label boundary (range image) takes its neighbour's label
  double miss = 0.0;       // chance per frame that a small object (pole, sign, trunk) is missed as a whole
  // One knob: confusion = rate, bleed = min(0.5, 2 * rate), miss = min(1, 2 * rate).
  static LabelNoise fromRate(double rate);
  // The network preset: range-dependent, blob-shaped, per-instance errors whose per-class IoU matches
  // RangeNet53++ (KNN) on the SemanticKITTI test set; moving objects get their static class.
  static LabelNoise network();
  bool any() const { return model == LabelNoiseModel::kNetwork || confusion > 0 || bleed > 0 || miss > 0; }
  const char* modelName() const { return model == LabelNoiseModel::kNetwork ? "network" : "iid"; }
};

// ---- Simulator ----------------------------------------------------------------------------------------

struct RayOrigin;  // render.cpp

struct SimConfig {
  std::uint64_t seed = 7;
  SensorConfig sensor = SensorConfig::hdl64();
  WorldConfig world;
  LabelNoise label_noise;
  int threads = 1;  // threads used inside one render() call (results do not depend on it)
};

struct Frame {
  int index = -1;                           // trajectory frame index
  double time = 0.0;                        // index * frame_dt (s)
  Mat4d pose = Mat4d::Identity();           // LiDAR -> world
  LabelledScan scan;                        // sensor-frame points; labels after label noise
  std::vector<float> intensity;             // 0..1 per point
  std::vector<std::uint32_t> clean_labels;  // labels before label noise (filled only when label noise is on)
  std::vector<std::uint16_t> beam;          // beam (row) of each point, 0 = top
  std::vector<std::uint16_t> column;        // azimuth column of each point
  // With motion distortion: when each point's ray fired, in seconds after the sweep's start (the frame's time
  // and pose); empty without it (every ray then fires from the frame's pose).
  std::vector<float> point_time;
  std::size_t mixed_points = 0;  // points whose range was blended across a depth edge
};

class Simulator {
 public:
  // Builds the world around the whole trajectory (not just the frames that will be rendered).
  Simulator(Trajectory trajectory, SimConfig config);

  const Trajectory& trajectory() const { return trajectory_; }
  const SimConfig& config() const { return config_; }
  const World& world() const { return world_; }
  int numFrames() const { return static_cast<int>(trajectory_.poses.size()); }

  // Thread-safe. Throws InputError for an index outside the trajectory.
  Frame render(int index) const;
  // Same, reusing `out`'s buffers; `threads` overrides config().threads (>= 1).
  void render(int index, Frame& out, int threads) const;

 private:
  Trajectory trajectory_;
  SimConfig config_;
  World world_;
  // Per-beam and per-column direction tables, and the rays blocked by the ego vehicle (column-major).
  std::vector<float> sin_el_, cos_el_, sin_az_, cos_az_;
  std::vector<std::uint8_t> ego_blocked_;
  // Per-laser calibration errors (empty unless sensor.laser_offsets): radians, radians, metres.
  std::vector<float> laser_el_, laser_az_, laser_bias_;
  // Spinning sensors with offsets: each beam's true elevation (sine, cosine) and azimuth turn (cosine, sine),
  // once per sensor rather than once per ray.
  std::vector<float> true_sin_el_, true_cos_el_, turn_cos_az_, turn_sin_az_;

  // render() in parts (render.cpp).
  struct FrameRays;
  struct RayImage;
  void castImage(const FrameRays& fr, int units, int threads, RayImage& img) const;
  void castSpinning(const FrameRays& fr, RayImage& img, int c_begin, int c_end) const;
  void castRosette(const FrameRays& fr, RayImage& img, int k_begin, int k_end) const;
  void castOne(const FrameRays& fr, const RayOrigin& ro, std::uint32_t ray, const Vec3f& ds, const Vec3f& dt,
               float bias, std::size_t px, RayImage& img) const;
  void compact(const FrameRays& fr, const RayImage& img, Frame& out) const;
};

// Applies label noise to a rendered frame in place (fills clean_labels). Exposed for tests; render()
// calls it when config().label_noise.any().
// wrap: the image's last column neighbours its first (spinning sensors; false for the rosette's pseudo image).
void applyLabelNoise(Frame& frame, const LabelNoise& noise, std::uint64_t seed, int beams, int columns,
                     bool wrap = true);

}  // namespace sglc::sim
