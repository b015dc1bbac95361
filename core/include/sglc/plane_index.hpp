// Plane lookup of one scan's planes: the nearest plane centroid to a point within a radius fixed when the index
// is built, among planes whose normal agrees. Refinement and the evidence ask it once per candidate plane of
// every hypothesis, so a lookup is one hash probe: each cell (of the radius' size) lists every plane within the
// radius of any point in it, and a point outside the planes' bounds grown by the radius is answered without a
// probe. Built once per query (planeIndexOf in fingerprint.hpp), then read-only.
#pragma once

#include <cstdint>
#include <vector>

#include "sglc/background.hpp"
#include "sglc/types.hpp"
#include "sglc/voxel_map.hpp"

namespace sglc {

class PlaneIndex {
 public:
  PlaneIndex() = default;
  // Throws InputError unless radius is positive and finite and every centroid finite and within 2^30 cells.
  PlaneIndex(const std::vector<Plane>& planes, double radius);

  // Nearest plane centroid to p closer than max_dist whose normal agrees with n (|cos| >= min_cos), the lowest
  // index among equally near ones; -1 if none. `planes` must be the vector the index was built from (one of
  // another length, a moved-from one say, is refused), and max_dist within [0, radius()] (InputError otherwise).
  int nearest(const std::vector<Plane>& planes, const Vec3f& p, const Vec3f& n, double max_dist, double min_cos) const;

  double radius() const { return radius_; }
  // Plane entries over all cells (memory and a measure of how much each probe scans).
  std::size_t entries() const { return members_.size(); }

 private:
  VoxelMap cells_;                                  // cell -> row
  std::vector<std::uint32_t> starts_;               // row r lists members_[starts_[r] .. starts_[r + 1])
  std::vector<std::int32_t> members_;               // ascending plane index within a row
  Vec3f lo_ = Vec3f::Zero(), hi_ = -Vec3f::Ones();  // planes' bounds grown by the radius (empty: lo > hi)
  std::size_t plane_count_ = 0;                     // planes.size() at build: the vector lookups must be given
  double radius_ = 0.0;
  double inv_cell_ = 1.0;
};

}  // namespace sglc
