// Labelled frames for an evaluation: a SemanticKITTI-layout sequence on disk (real or written by sglc-sim),
// or the simulator rendering in memory. Frames are addressed by their frame number (KITTI index).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sglc/bag_drive.hpp"
#include "sglc/types.hpp"

namespace sglc::eval {

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Frame numbers selected for the run, ascending.
  virtual const std::vector<int>& frames() const = 0;
  // Every frame number with a ground-truth pose (the whole trajectory, also unselected frames).
  virtual bool hasPose(int frame) const = 0;
  // LiDAR -> world pose of a frame (hasPose must be true).
  virtual Mat4d pose(int frame) const = 0;
  // Loads or renders a frame. Thread-safe. Throws InputError for a frame it does not have.
  virtual LabelledScan scan(int frame) const = 0;
  virtual std::string describe() const = 0;
};

struct SimSourceOptions {
  std::string poses;   // KITTI poses file; empty: the simulator's built-in route
  std::string calib;   // KITTI calib.txt with the Tr line (needed with poses)
  std::string frames;  // selection "a:b:s,..." (sglc-sim syntax); empty: all
  std::uint64_t seed = 7;
  double label_noise = 0;  // LabelNoise::fromRate
  int beams = 64;          // SensorConfig::preset: 32 (HDL-32E-like), 64 (HDL-64E-like), 128
};
std::unique_ptr<FrameSource> simulatedSource(const SimSourceOptions& options);

// dir: a sequence directory (velodyne/, labels/, optional poses.txt + calib.txt). poses.txt holds camera poses
// (KITTI convention); with calib.txt they become LiDAR poses. `frames` selects by frame number.
// deskew: how scans with point_times/ files are de-skewed (sglc/deskew.hpp). `dir` may be a bag (sglc::isBag):
// its clouds, numbered by their index on the topic, with `bag`'s options (de-skewed by the bag drive's own
// motion unless kOff).
// A bag needs its PointCloud2 topic and the poses (Odometry topic or tf frame) the protocols compare with.
enum class DeskewMotion {
  kOff,               // read as they are
  kNextFrame,         // the motion from the frame's pose to the next frame's, as a recorded drive has it
  kPreviousKeyframe,  // as the server does it: the constant velocity from the previous selected frame (its
                      // previous stored scan), at most closing::kMaxSweepGap before; the first is left as it is
};
std::unique_ptr<FrameSource> directorySource(const std::string& dir, const std::string& frames,
                                             DeskewMotion deskew = DeskewMotion::kNextFrame,
                                             const BagDriveOptions& bag = {});

// The same frames with their labels removed (points only), to measure the label-free path: the engine's
// built-in labeller labels them.
std::unique_ptr<FrameSource> withoutLabels(std::unique_ptr<FrameSource> source);

}  // namespace sglc::eval
