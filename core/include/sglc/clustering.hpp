// Instance clustering of landmark-class points: connected components over range-adaptive polar voxels.
// O(N) in the number of points (hashing + union-find), and independent of the sensor's beam layout.
#pragma once

#include <cstdint>
#include <vector>

#include "sglc/config.hpp"
#include "sglc/types.hpp"

namespace sglc {

struct Cluster {
  int cls = -1;                       // node class index
  std::vector<std::uint32_t> points;  // indices into the scan, ascending
};

// point_class[i] is the node class of point i, or -1 to skip it. Points of different classes never join.
// Clusters are returned in a stable order (by class, then by their first point index).
std::vector<Cluster> clusterInstances(const Points& points, const std::vector<std::int8_t>& point_class,
                                      const ClusterConfig& config);

}  // namespace sglc
