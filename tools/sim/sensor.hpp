// Sensor geometry beyond the preset tables: named presets, per-laser calibration errors, the rosette
// scanner's ray pattern, and the pose of the sensor at a moment within a sweep (rolling shutter).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "sim/simulator.hpp"

namespace sglc::sim {

// The names --sensor accepts, in the order the help text lists them.
const std::vector<std::string>& sensorPresetNames();
// A named preset (vlp16, hdl32, hdl64, os1-128, rosette). Throws InputError for any other name.
SensorConfig sensorPreset(const std::string& name);

// Fixed calibration errors of one sensor unit, one entry per laser (spinning: per beam; rosette: per
// channel). Drawn from the seed, which plays the role of the unit's serial number.
struct LaserOffsets {
  std::vector<float> elevation_rad, azimuth_rad, range_bias_m;
};
// Standard deviations of the offsets (see tools/sim/README.md, "Per-laser calibration offsets").
inline constexpr double kLaserElevationSigmaDeg = 0.05;
inline constexpr double kLaserAzimuthSigmaDeg = 0.1;
inline constexpr double kLaserRangeSigmaM = 0.015;
LaserOffsets laserOffsets(int lasers, std::uint64_t seed);

// One rosette ray: nominal direction (azimuth left-positive, elevation up-positive, radians), its laser
// channel, and the cell of the pseudo range image it is binned into (row 0 = top, column 0 = rightmost).
struct RosetteRay {
  float azimuth, elevation;
  std::uint16_t channel, row, column;
};
// The rays of frame `index` in firing order (ray k fires at k / rays * frame_dt after the sweep starts).
// The rose curve keeps running from frame to frame, so no two frames share a pattern.
void rosetteRays(const SensorConfig& sensor, std::uint64_t seed, int index, std::vector<RosetteRay>& out);

// The LiDAR pose (LiDAR -> world) at fraction `alpha` (0..1) of frame `index`'s sweep: the frame's pose
// moved on by alpha of the motion to the next frame (at the last frame, the motion from the previous one).
// Translation is linear, rotation a slerp.
class SweepMotion {
 public:
  SweepMotion(const std::vector<Mat4d>& poses, int index);
  Mat4d at(double alpha) const;

 private:
  Mat4d start_;
  Mat4d step_;  // one frame's motion in the start pose's axes
  Eigen::Quaterniond rotation_;
};

// Mixed pixels at depth edges, on a cast image (pixel -> range, point, label, intensity; range <= 0 = no
// return). A return whose neighbour (pixel +- stride; with wrap, modulo the image size) differs in range by
// more than 1 m is, with chance `rate`, moved to a range between the two along its own ray and takes the
// nearer (foreground) return's label. Returns how many pixels were mixed.
std::size_t applyMixedPixels(std::vector<float>& range, std::vector<Vec3f>& point, std::vector<std::uint32_t>& label,
                             std::vector<float>& intensity, std::size_t stride, bool wrap, double rate,
                             std::uint64_t key);

}  // namespace sglc::sim
