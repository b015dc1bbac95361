// The evaluation protocols (docs/EVALUATION.md, the paper's definitions in docs/METHOD.md). Each runs over a
// frame source and a back-end, writes its CSV files into Run::out and its figures into Run::summary.
#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "backend.hpp"
#include "pair_lists.hpp"
#include "report.hpp"
#include "source.hpp"

namespace sglc::eval {

struct Run {
  const FrameSource& source;
  Backend& backend;
  int threads;            // frames loaded or rendered ahead
  std::set<int>& stored;  // frames the back-end holds (shared by the protocols of one invocation)
  ordered_json summary;
  Timings timings;
  std::string out;  // directory of this protocol's files
};

// Stores the given frames of `source` that are not stored yet (Run::stored), in order, loading ahead.
void storeFrames(Run& run, const FrameSource& source, const std::vector<int>& frames);

// Pairs: each listed pair verified (no refinement); PR curve over the pair labels.
void pairProtocol(Run& run, const std::vector<PairRow>& rows);

// Pose: every loop pair (label 1) registered as a known loop; RR, RTE, RRE against the poses, or against the
// rows' T with gt_from_file.
void poseProtocol(Run& run, const std::vector<PairRow>& rows, bool gt_from_file);

// Sequence: every frame queries the frames stored before it, then is stored. A true loop is nearer than
// positive_m (or listed in gt_list, when given); a top-1 candidate between positive_m and negative_m counts as
// no detection. Must run before any other protocol stores frames.
struct SequenceOptions {
  double positive_m = 3.0;
  double negative_m = 20.0;
  const std::vector<PairRow>* gt_list = nullptr;
};
void sequenceProtocol(Run& run, const LoopQuery& query, const SequenceOptions& options);

// Relocalization: every frame of `map` is stored, then every frame of the run's source (another drive in the
// same world frame: another time, another sensor) asks where it is, without being stored. A query has a true
// place when a map frame lies within positive_m; a verified top-1 candidate is true within positive_m, false
// beyond negative_m, and in between neither (counted in top1_in_band).
void relocalizationProtocol(Run& run, const FrameSource& map, const LoopQuery& query, const SequenceOptions& options);

// SLAM: the frames go to a running server as one or two robots with drifting odometry and loop queries; the
// server's pose graph corrects them. Two robots: the first drives the first 60 % of the frames, the second the
// last 60 %, with its odometry in an unrelated frame.
struct SlamOptions {
  std::string server;
  std::string token;
  std::string map;
  double odom_noise = 0.01;
  int robots = 1;
  std::uint64_t seed = 7;
  int exclude_recent = 100;
  bool keep_map = false;  // leave the map on the server (--keep-maps)
};
void slamProtocol(Run& run, const SlamOptions& options);

}  // namespace sglc::eval
