// Everything later stages need about one scan, computed once: the semantic graph and its descriptors,
// downsampled instance points, a labelled BEV background cloud and background plane features.
// A fingerprint serialises to versioned bytes and back exactly, so a stored scan is never re-clustered
// and can itself serve as a query.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <vector>

#include "sglc/background.hpp"
#include "sglc/derived_memo.hpp"
#include "sglc/descriptors.hpp"
#include "sglc/graph.hpp"
#include "sglc/plane_index.hpp"
#include "sglc/registration.hpp"

namespace sglc {

struct ViewContext;

struct Fingerprint {
  // Parameters the stored data depends on (kept so that a loaded fingerprint is self-describing).
  DescriptorLayout layout;
  float d_max = 60.0f;
  float d_i = 2.0f;
  float background_cell = 0.5f;
  float plane_voxel = 1.0f;
  // Structure points above this height (sensor frame) were left out of `background` (format 3 on); +inf for
  // fingerprints of formats 1 and 2, whose background view holds every height.
  float background_max_z = std::numeric_limits<float>::infinity();
  // The structure classes of `background` and `planes` were computed by the built-in labeller (the scan came
  // without labels; format 4 on, false for older formats). Background agreement with such a scan compares
  // structure against road, not building against vegetation (StructureClasses::kMerged).
  bool labeller_structure = false;

  std::vector<Node> nodes;
  std::vector<std::uint32_t> instance_offsets;  // node i owns instance_points[offsets[i] .. offsets[i+1])
  Points instance_points;                       // sensor frame, on a 1 cm grid
  std::vector<BevCell> background;
  std::vector<Plane> planes;      // centroid on a 1 cm grid, normal on a 1/32767 grid
  std::vector<float> descriptor;  // scan descriptor (layout.scanDim())
  std::uint32_t num_points = 0;   // points in the source scan

  // Derived on construction and on load (not serialised): node descriptors.
  Eigen::MatrixXf node_descriptors;
  // Derived on first use and kept: the view context (viewContextOf in view_context.hpp) and the plane lookup
  // (planeIndexOf below). A stored scan that never serves as a query never builds its plane lookup.
  DerivedMemo<ViewContext> view_memo;
  DerivedMemo<PlaneIndex> plane_memo;

  InstanceView instance(int node) const {
    return {instance_points.data() + instance_offsets[node],
            static_cast<int>(instance_offsets[node + 1] - instance_offsets[node])};
  }
  // Recomputes the derived members from the stored ones.
  void finalize();
};

// The lookup of fp's planes within `radius` metres (PlaneIndex), built on first use and kept with fp for that
// radius. Thread-safe.
std::shared_ptr<const PlaneIndex> planeIndexOf(const Fingerprint& fp, double radius);

// 2: the scan descriptor's edge histogram is soft-binned. 3: the background view holds only structure within
// background_max_z of the sensor, and the descriptor's background part is the structure spectrum of that view
// (the ring key of building and road points before). 4: a flags byte after the height band (bit 0:
// labeller_structure; other bits must be 0). Blobs of versions 1 and 2 are read with their descriptor
// recomputed from their stored nodes and background view, so a loaded fingerprint's descriptor is always of the
// current definition (serialize writes version 4; a version-3 blob reads as it was, with labeller_structure
// false).
inline constexpr std::uint32_t kFingerprintVersion = 4;

std::vector<std::uint8_t> serialize(const Fingerprint& fp);
// Throws InputError on a truncated, corrupted (checksum), foreign or newer-version blob. A blob of version 1 or
// 2 comes back with its scan descriptor recomputed (and so serialises to different bytes): the layout keeps its
// length (2 * rings old ring-key values become rings / 3 rings of orders 0-2 when rings divides by 3, else
// rings rings of order 0) and the spectrum's other settings are DescriptorConfig's defaults.
Fingerprint deserialize(std::span<const std::uint8_t> bytes);

// The format version a blob's header names (0 when it is too short or not a fingerprint). Nothing is checked
// beyond the magic: deserialize does that.
std::uint32_t fingerprintFormat(std::span<const std::uint8_t> bytes);

// Whether two fingerprints describe the same scan: equal in everything stored, and scan descriptors equal
// within float rounding (one read from an older format had its descriptor recomputed, which can differ from a
// fresh computation in the last bits). When their background height bands differ (a scan stored by a build
// before format 3, sent again), the background view and the descriptor built from it are left out.
// labeller_structure is left out too: a scan stored before format 4 has it false whatever labelled it.
bool sameScan(const Fingerprint& a, const Fingerprint& b);

}  // namespace sglc
