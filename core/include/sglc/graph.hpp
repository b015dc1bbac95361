// The semantic graph: one node per landmark instance, an edge between nodes closer than d_max.
#pragma once

#include <cstdint>
#include <vector>

#include "sglc/clustering.hpp"
#include "sglc/config.hpp"
#include "sglc/types.hpp"

namespace sglc {

struct Node {
  Vec3f center = Vec3f::Zero();  // centre of the instance's box, sensor frame (m)
  Vec3f size = Vec3f::Zero();    // yaw-invariant box: length >= width (horizontal PCA extents), height
  std::uint8_t cls = 0;          // node class index
};

// Node for one cluster: horizontal PCA box, so the size does not change with the viewing direction.
Node makeNode(const Points& points, const Cluster& cluster);

// Nodes for all clusters; when there are more than max_nodes, the ones with most points are kept.
// Returns the kept nodes and, in kept_clusters, the index of each node's cluster.
std::vector<Node> buildNodes(const Points& points, const std::vector<Cluster>& clusters, const GraphConfig& config,
                             std::vector<int>* kept_clusters);

// Symmetric 0/1 adjacency with ones on the diagonal (as the reference).
Eigen::MatrixXd adjacency(const std::vector<Node>& nodes, double d_max);

}  // namespace sglc
