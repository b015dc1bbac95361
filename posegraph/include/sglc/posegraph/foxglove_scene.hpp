// A map's pose graph as messages in Foxglove's own schemas (JSON encoding, JSON Schema), which Foxglove shows
// without configuration: the one description the MCAP export and the live view (sglc-server --viz-listen) share.
// Topics, relative to the map (the export prefixes "/sglc/", the live view "/sglc/<map>/"; robot names are
// percent-encoded, topicName):
//   trajectory/<robot>  foxglove.PosesInFrame  the robot's scans at their optimised poses, frame "map"
//   odometry/<robot>    foxglove.PosesInFrame  the same scans' odometry as the robot sent it, each session
//                                              placed where its first scan is
//   loops               foxglove.SceneUpdate   line lists: intra-robot loops green, inter-robot loops red,
//                                              with their counts and mean probability as metadata
//   loop_list           sglc.LoopList          every loop: its ends (robot, seq), score, probability and the
//                                              weight the robust loss gives it
//   keyframe            foxglove.PointCloud    a scan's points (voxel-downsampled) at its pose
//   events              sglc.MapEvent          the pose graph's newest solve (WatchMap's event)
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "sglc/posegraph/graph_export.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/types.hpp"

namespace sglc::posegraph {

struct FoxgloveTopic {
  std::string topic;        // relative to the map, e.g. "trajectory/robot%2F1"
  std::string schema_name;  // e.g. "foxglove.PosesInFrame"
  std::string message;      // the JSON message
};

// The JSON Schema of a schema name used here. Throws std::invalid_argument for any other name.
const std::string& foxgloveSchema(const std::string& schema_name);

// A name as one topic level: '%' and '/' percent-encoded ("%25", "%2F"), every other byte as it is.
std::string topicName(const std::string& name);

// The newest scan stamp of the graph in nanoseconds (0 without plausible stamps).
std::uint64_t newestStampNs(const ExportedGraph& graph);

// Trajectories and odometry per robot, then loops and loop_list, stamped `stamp_ns`.
std::vector<FoxgloveTopic> foxgloveScene(const ExportedGraph& graph, std::uint64_t stamp_ns);

// foxglove.PointCloud of `points` (in the scan's frame) at `pose` in frame "map", keeping the first point of each
// voxel of `voxel_m` (> 0) in input order, at most `max_points` (the first voxels in scan order). Points farther
// than min(500 km, 2^19 voxels) on any axis are dropped (210 km at 0.4 m).
std::string foxglovePointCloud(const Points& points, const Mat4d& pose, std::uint64_t stamp_ns, double voxel_m,
                               std::size_t max_points);

// sglc.MapEvent of a graph event.
std::string foxgloveMapEvent(const GraphEvent& event);

// sglc.MapStats of a map's statistics: scans, and for lifelong maps places, versions and what was retired.
std::string foxgloveMapStats(const storage::Stats& stats);

}  // namespace sglc::posegraph
