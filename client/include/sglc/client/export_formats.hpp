// A map's loops in the formats other tools read: JSON lines and CSV. The whole pose graph (g2o with odometry
// edges, JSON) comes from the server: PoseGraph.ExportGraph, `sglc export`.
#pragma once

#include <nlohmann/json.hpp>
#include <ostream>
#include <vector>

#include "sglc/v1/sglc.pb.h"

namespace sglc::client {

nlohmann::ordered_json loopJson(const v1::LoopEdge& loop);
void writeLoopsCsv(const std::vector<v1::LoopEdge>& loops, std::ostream& out);

}  // namespace sglc::client
