// Writes a simulated sequence in the SemanticKITTI layout, with ground truth:
//   velodyne/NNNNNN.bin, labels/NNNNNN.label   output frames 0..N-1 (frames.txt maps them to trajectory frames)
//   poses.txt        LiDAR poses in the world frame (= LiDAR frame of trajectory frame 0), one row per output frame
//   calib.txt        P0..P3 = [I|0] and Tr = identity: poses.txt is already in the LiDAR frame, so loaders that
//                    apply inv(Tr) * P * Tr get it unchanged
//   times.txt        seconds of each output frame (trajectory index * frame_dt)
//   frames.txt       trajectory frame index of each output frame
//   pairs_distance.txt   "i j label" (SSC style): i later, j earlier; 1 = loop (< 3 m), 0 = non-loop (> 20 m)
//   loop_distance4.txt   "i j" + 12 numbers: i earlier, j later, row-major 3x4 T with p_j = T * p_i
//   odometry.txt     (only with odometry noise) drifting LiDAR poses, same convention as poses.txt
//   sim_info.json    everything needed to reproduce the output, and a summary (with the per-class IoU of the
//                    written labels against the true ones)
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "sim/ground_truth.hpp"
#include "sim/label_iou.hpp"
#include "sim/simulator.hpp"

namespace sglc::sim {

struct SequenceOptions {
  std::string out_dir;
  std::vector<int> frames;     // trajectory frame indices, ascending
  std::string selection_spec;  // as given by the user (recorded in sim_info.json)
  PairListConfig pairs;
  double loop_pose_m = 4.0;
  OdometryNoise odometry;
  int threads = 2;  // frames rendered in parallel (each frame single-threaded)
  // An output folder that already holds scans (NNNNNN.bin / NNNNNN.label) is refused, so that runs never mix;
  // with overwrite, those scans are deleted first.
  bool overwrite = false;
  // Called from the calling thread about twice a second, and once at the end.
  std::function<void(int done, int total, double seconds)> progress;
};

struct SequenceSummary {
  int frames = 0;
  std::uint64_t points = 0;
  std::uint64_t bytes = 0;  // written by velodyne/ and labels/
  double seconds = 0.0;     // rendering + writing frames
  double frames_per_second = 0.0;
  std::size_t positives = 0, negatives = 0, loop_rows = 0, reverse_loop_rows = 0;
  // Written labels vs true labels over all frames written (all IoU 1 without label noise).
  LabelIouCounts label_iou;
};

SequenceSummary writeSequence(const Simulator& sim, const SequenceOptions& options);

}  // namespace sglc::sim
