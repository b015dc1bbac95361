// Background (road, building, fence, vegetation) features: the ring key for retrieval, a compact labelled
// BEV cloud for verification, and plane features for pose refinement.
#pragma once

#include <cstdint>
#include <vector>

#include "sglc/config.hpp"
#include "sglc/labels.hpp"
#include "sglc/types.hpp"

namespace sglc {

// One occupied cell of the labelled bird's-eye view; position = (ix + 0.5, iy + 0.5) * cell size.
struct BevCell {
  std::int16_t ix = 0;
  std::int16_t iy = 0;
  // Background value: the structure class (fence, building, vegetation) with most points, ties to the higher
  // priority; road only where no structure point falls.
  std::uint8_t cls = 0;
};

struct Plane {
  Vec3f centroid = Vec3f::Zero();
  Vec3f normal = Vec3f::UnitZ();
  std::uint8_t cls = 0;  // Background value
};

// Rotation-invariant ring key: for building and road, the number of occupied one-degree sectors per ring.
// 2 * rings values, L2-normalised; all zero when no ring is occupied.
std::vector<float> ringKey(const Points& points, const std::vector<Background>& point_bg,
                           const DescriptorConfig& config);

// Labelled BEV cells within max range, sorted by (iy, ix).
std::vector<BevCell> bevCells(const Points& points, const std::vector<Background>& point_bg, double cell,
                              double max_range);

// Plane features of road, building and fence points: one per voxel with enough, flat enough points.
// Normals face the sensor. Sorted by voxel.
std::vector<Plane> extractPlanes(const Points& points, const std::vector<Background>& point_bg,
                                 const FingerprintConfig& config);

// Agreement of two labelled BEV clouds once `candidate` is moved by T_q_c into the query frame:
// (cells holding the same class) / (cells occupied in either), over a square grid of +-radius around the query.
// A grid cell's class is the majority of the stored cells falling in it, by the same rule as BevCell::cls.
double bevAgreement(const std::vector<BevCell>& query, const std::vector<BevCell>& candidate, double stored_cell,
                    const Mat4d& T_q_c, double grid_cell, double radius);

}  // namespace sglc
