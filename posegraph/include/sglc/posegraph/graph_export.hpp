// A map's pose graph as the optimiser weighs it, for other back-ends: every scan with an odometry pose as a node
// (at its current pose), odometry edges between consecutive scans of a session and every verified loop that
// joins two nodes, each with the information the optimiser gives it; the loops that cannot join the graph,
// with the reason. Written as g2o (VERTEX_SE3:QUAT / EDGE_SE3:QUAT with a side file of node ids) or JSON.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::posegraph {

struct ExportedGraph {
  struct Node {
    std::int64_t scan_id = 0;
    std::string robot, session;
    std::int64_t seq = 0;
    std::optional<double> stamp;
    Mat4d odometry = Mat4d::Identity();  // scan -> its session's odometry frame, as ingested
    Mat4d pose = Mat4d::Identity();      // scan -> map frame: optimised, else odometry through its session frame
    bool optimised = false;
  };
  // A relative-pose measurement T (maps `to`'s points into `from`'s frame) between nodes[from] and nodes[to],
  // with the information of the optimiser's residual: translation, then twice the vector part of the rotation
  // error quaternion (about the rotation vector), as posegraph/src/relative_pose_error.hpp defines it. A loop's
  // information includes `weight`, its robust loss's weight at the current poses (1 for a loop that fits,
  // near 0 for one the server discounts), so that plain least squares on the export has the server's
  // solution as its own.
  struct Edge {
    std::size_t from = 0, to = 0;
    Mat4d T = Mat4d::Identity();
    Mat6d information = Mat6d::Identity();
    std::int64_t loop_id = 0;  // 0: odometry
    std::optional<double> probability;
    double score = 0;  // the loop's verification score
    double weight = 1.0;
  };
  struct LeftOut {
    storage::LoopRecord loop;
    std::string reason;
  };
  std::vector<Node> nodes;  // by robot, session, seq: g2o ids are indices into it
  std::vector<Edge> edges;  // odometry edges, then loops by id
  std::vector<LeftOut> left_out;
  std::int64_t graph_version = 0;
};

// `robots`: the robots whose scans to export (empty: every robot); loops to another robot's scans are left out.
// The map must exist (storage kNotFound otherwise).
ExportedGraph exportGraph(const storage::MapStore& store, const std::string& map, const GraphOptimiserOptions& options,
                          const std::vector<std::string>& robots = {});

// g2o: VERTEX_SE3:QUAT per node (id = index, at its pose), EDGE_SE3:QUAT per edge with g2o's information (the
// rotation rows and columns scaled by 2: g2o's error is the quaternion's vector part, half ours), upper
// triangle; `ids` gets the CSV "id,scan_id,robot,session,seq,stamp,optimised". Names are quoted per RFC 4180.
void writeG2o(const ExportedGraph& graph, std::ostream& g2o, std::ostream& ids);
// The loops left out, as CSV "loop_id,query_scan,candidate_scan,reason".
void writeLeftOutCsv(const ExportedGraph& graph, std::ostream& out);
// MCAP in Foxglove's own schemas (JSON messages, JSON Schema), which Foxglove shows without configuration: the
// topics of foxgloveScene (foxglove_scene.hpp) under "/sglc/", stamped with the newest scan stamp (0 without).
// `points`, when set, gives a scan's points in its own frame (nullopt: none kept): each node's go out on
// "/sglc/keyframes/<robot>" as foxglove.PointCloud at its pose, one point per voxel of `voxel_m`, stamped with the
// scan's stamp, in node order until kMaxKeyframeBytes of them are written. Returns the number of keyframes written.
inline constexpr std::size_t kMaxKeyframeBytes = std::size_t{256} << 20;
using ScanPoints = std::function<std::optional<Points>(std::int64_t scan_id)>;
std::size_t writeGraphMcap(const ExportedGraph& graph, std::ostream& out, const ScanPoints& points = {},
                           double voxel_m = 1.0);
// One JSON document: nodes, edges (information as 36 values, the optimiser's convention) and left_out loops.
void writeGraphJson(const ExportedGraph& graph, std::ostream& out);

}  // namespace sglc::posegraph
