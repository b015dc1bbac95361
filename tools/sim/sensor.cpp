// Sensor presets (spinning and rosette), named presets for --sensor, and per-laser calibration offsets.
#include <cmath>
#include <numbers>

#include "sim/rng.hpp"
#include "sim/sensor.hpp"

namespace sglc::sim {
namespace {

// A spinning sensor whose beams are spread evenly from `top_deg` down to `bottom_deg`.
SensorConfig uniformSpinning(const char* name, int beams, double top_deg, double bottom_deg, int columns,
                             double max_range) {
  SensorConfig s;
  s.name = name;
  for (int k = 0; k < beams; ++k) s.elevation_deg.push_back(top_deg - k * (top_deg - bottom_deg) / (beams - 1));
  s.columns = columns;
  s.max_range = max_range;
  return s;
}

}  // namespace

SensorConfig SensorConfig::hdl64() {
  SensorConfig s;
  s.name = "hdl64";
  // Upper block: 32 lasers from +2 deg down at 1/3 deg; lower block: 32 lasers from -8.83 to -24.8 deg.
  for (int k = 0; k < 32; ++k) s.elevation_deg.push_back(2.0 - k / 3.0);
  for (int k = 0; k < 32; ++k) s.elevation_deg.push_back(-8.83 - k * (24.8 - 8.83) / 31.0);
  s.columns = 2083;
  s.max_range = 80.0;
  return s;
}

SensorConfig SensorConfig::hdl32() { return uniformSpinning("hdl32", 32, 10.67, -30.67, 1800, 100.0); }

SensorConfig SensorConfig::beams128() { return uniformSpinning("beams128", 128, 15.0, -25.0, 1800, 120.0); }

SensorConfig SensorConfig::preset(int beams) {
  if (beams == 64) return hdl64();
  if (beams == 32) return hdl32();
  if (beams == 128) return beams128();
  if (beams < 1 || beams > 1024)
    throw InputError("sensor: beams must be between 1 and 1024, got " + std::to_string(beams));
  SensorConfig s = hdl64();
  s.name = "uniform" + std::to_string(beams);
  s.elevation_deg.clear();
  for (int k = 0; k < beams; ++k) s.elevation_deg.push_back(beams == 1 ? -8.0 : 2.0 - k * 26.8 / (beams - 1));
  return s;
}

SensorConfig& SensorConfig::noiseFree() {
  range_noise = 0.0;
  dropout = 0.0;
  far_dropout = 0.0;
  grazing_dropout = 0.0;
  glass_dropout = 0.0;
  intensity_noise = false;
  return *this;
}

SensorConfig SensorConfig::vlp16() { return uniformSpinning("vlp16", 16, 15.0, -15.0, 1800, 100.0); }

// The OS1-128 runs at 512, 1024 or 2048 columns per revolution; 1024 at 10 Hz is its default mode.
SensorConfig SensorConfig::os1_128() { return uniformSpinning("os1-128", 128, 22.5, -22.5, 1024, 120.0); }

// The Avia fires 240 000 points/s, so 24 000 per 100 ms frame, over 70.4 deg x 77.2 deg; its range is 190 m
// at 80 % reflectivity, capped here at the world's 150 m. The 128 x 128 pseudo image (cells of about 0.55 x
// 0.6 deg) is close to the mean ray spacing, so label noise and mixed pixels see sensible neighbours.
SensorConfig SensorConfig::rosette() {
  SensorConfig s;
  s.name = "rosette";
  s.rosette_rays = 24000;
  const int rows = 128;
  for (int k = 0; k < rows; ++k)
    s.elevation_deg.push_back(s.rosette_fov_v_deg / 2 - (k + 0.5) * s.rosette_fov_v_deg / rows);
  s.columns = 128;
  s.max_range = 150.0;
  return s;
}

const std::vector<std::string>& sensorPresetNames() {
  static const std::vector<std::string> names = {"vlp16", "hdl32", "hdl64", "os1-128", "rosette"};
  return names;
}

SensorConfig sensorPreset(const std::string& name) {
  if (name == "vlp16") return SensorConfig::vlp16();
  if (name == "hdl32") return SensorConfig::hdl32();
  if (name == "hdl64") return SensorConfig::hdl64();
  if (name == "os1-128") return SensorConfig::os1_128();
  if (name == "rosette") return SensorConfig::rosette();
  throw InputError("sensor: unknown preset '" + name + "' (vlp16, hdl32, hdl64, os1-128 or rosette)");
}

LaserOffsets laserOffsets(int lasers, std::uint64_t seed) {
  LaserOffsets o;
  constexpr double kDeg = std::numbers::pi / 180.0;
  for (int k = 0; k < lasers; ++k) {
    const std::uint64_t key = hashKeys(seed, 0x5E7A1ULL, static_cast<std::uint64_t>(k));
    o.elevation_rad.push_back(static_cast<float>(kLaserElevationSigmaDeg * kDeg * normalFromBits(mix64(key ^ 1))));
    o.azimuth_rad.push_back(static_cast<float>(kLaserAzimuthSigmaDeg * kDeg * normalFromBits(mix64(key ^ 2))));
    o.range_bias_m.push_back(static_cast<float>(kLaserRangeSigmaM * normalFromBits(mix64(key ^ 3))));
  }
  return o;
}

}  // namespace sglc::sim
