// The pose graph kept with each map: verified loops, the scans as nodes, optimised poses and session frames,
// and the graph's version.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "store_core.hpp"

namespace sglc::storage::pose_graph_tables {

std::int64_t addLoop(StoreCore& core, const std::string& map, const LoopRecord& loop);
std::vector<LoopRecord> loops(const StoreCore& core, const std::string& map, std::int64_t after_id, std::int64_t limit);
std::vector<GraphNodeRecord> nodes(const StoreCore& core, const std::string& map, std::int64_t after_scan);
std::int64_t saveOptimised(StoreCore& core, const std::string& map, std::int64_t map_id,
                           const std::vector<OptimisedPose>& poses, const std::vector<SessionFrame>& frames,
                           std::int64_t through_loop);
std::vector<OptimisedPose> optimisedPoses(const StoreCore& core, const std::string& map, const std::string& robot,
                                          const std::string& session, std::int64_t after_scan, std::int64_t limit);
std::vector<SessionFrame> sessionFrames(const StoreCore& core, const std::string& map);
std::int64_t graphVersion(const StoreCore& core, const std::string& map);
std::int64_t optimisedThroughLoop(const StoreCore& core, const std::string& map);

}  // namespace sglc::storage::pose_graph_tables
