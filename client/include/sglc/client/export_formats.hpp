// A map's loops in the formats other tools read: JSON lines, CSV, and g2o (VERTEX_SE3:QUAT / EDGE_SE3:QUAT,
// which g2o, GTSAM's readG2o and g2o viewers load).
//
// g2o edges go from the query scan i to the candidate scan j with measurement T_ij = t_query_candidate, and
// information upper-triangular over (x, y, z, qx, qy, qz). Our information is over (t, r) with r the rotation
// vector of a right perturbation; g2o's error uses the quaternion's vector part, about r / 2, so the
// rotation rows and columns are scaled by 2 (rotation block x4). A loop stored without information gets
// sigma 0.1 m and 1 deg.
#pragma once

#include <nlohmann/json.hpp>
#include <ostream>
#include <vector>

#include "sglc/v1/sglc.pb.h"

namespace sglc::client {

nlohmann::ordered_json loopJson(const v1::LoopEdge& loop);
void writeLoopsCsv(const std::vector<v1::LoopEdge>& loops, std::ostream& out);
// `vertices`: the poses of the scans at the loops' ends. Ends without one (scans ingested without an odometry
// pose are no graph nodes) are written at the identity; returns how many.
std::size_t writeLoopsG2o(const std::vector<v1::LoopEdge>& loops, const std::vector<v1::ScanPose>& vertices,
                          std::ostream& out);

}  // namespace sglc::client
