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

// Labelled BEV cells within max range, sorted by (iy, ix). Structure points (fence, building, vegetation) higher
// than max_z in the sensor frame are left out: the band every LiDAR sees (FingerprintConfig::background_max_z_m).
std::vector<BevCell> bevCells(const Points& points, const std::vector<Background>& point_bg, double cell,
                              double max_range, double max_z);

// Rotation-invariant background part of the scan descriptor (ours). The structure cells of a labelled BEV
// (`cell` metres) between config.ring_min_m and ring_max_m fall, in two parts (building and fence; vegetation),
// in `rings` rings of config.sectors sectors; each cell is shared between the two rings whose centres are
// nearest, linearly (tapering to nothing half a ring beyond either edge), and a (ring, sector) holds at most 1. Per
// part and ring, the magnitudes |sum_s occupied(s) exp(-2 pi i k s / sectors)| for k = 0..orders: order 0 counts the
// occupied sectors, higher orders keep how the structure spreads around the sensor, and turning the scan changes only
// their phases. 2 * rings * (orders + 1) values in that order (part, ring, k), unnormalised; all zero without
// structure.
std::vector<float> structureSpectrum(const std::vector<BevCell>& cells, double cell, int rings, int orders,
                                     const DescriptorConfig& config);

// How much of the horizon a scan saw (ours): of 36 azimuth sectors of 10 deg around the sensor, the share holding
// a labelled BEV cell (road or structure) beyond `min_range` metres, in degrees (0-360). A spinning LiDAR sees
// road all around it, so 360 less what a truck beside it hides; a forward-looking solid-state sensor sees its
// field of view (about 70 deg for a Livox Avia's rosette). Cells nearer than min_range have too coarse a bearing;
// the background-only loop gate (VerifyConfig::background_min_view_deg) counts from kViewSpanMinRangeM.
inline constexpr double kViewSpanMinRangeM = 4.0;
double viewSpanDeg(const std::vector<BevCell>& cells, double cell, double min_range = kViewSpanMinRangeM);

// Plane features of road, building and fence points: one per voxel with enough, flat enough points.
// Normals face the sensor. Sorted by voxel.
std::vector<Plane> extractPlanes(const Points& points, const std::vector<Background>& point_bg,
                                 const FingerprintConfig& config);

// Agreement of two labelled BEV clouds once `candidate` is moved by T_q_c into the query frame, over a square
// grid of +-radius around the query whose cells take the majority class of the stored cells falling in them
// (the rule of BevCell::cls). Judged are the cells where either view has structure (fence, building,
// vegetation) and both views have seen something in the cell or a neighbouring one; the value is the share of
// them holding the same class in both (0 when none is judged). Road against road says little (any two streets
// agree), and structure that one view has no return near was hidden from it or outside its field of view: a
// sparser or differently aimed sensor is not counted against (ours; the paper compares background descriptors,
// the reference scores a polar grid by priority class). kMerged compares structure against road only
// (building, fence and vegetation count as one class): for views whose classes the built-in labeller computed,
// whose split of structure into building and vegetation is not repeatable from visit to visit. `field`, when
// given, limits the judged cells to the directions the query looked in: field->size() equal azimuth sectors
// around the query's origin, counted from -pi as the view context's (a narrow view's own field,
// sglc/view_context.hpp); null or empty: no limit.
enum class StructureClasses { kCompared, kMerged };
double bevAgreement(const std::vector<BevCell>& query, const std::vector<BevCell>& candidate, double stored_cell,
                    const Mat4d& T_q_c, double grid_cell, double radius,
                    StructureClasses classes = StructureClasses::kCompared, const std::vector<bool>* field = nullptr);

}  // namespace sglc
