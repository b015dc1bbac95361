// The view context (ours): where structure lies around the sensor, compared only in the directions a narrow
// view saw. A solid-state sensor's 70 deg wedge and a spinning LiDAR's full turn of the same place share the
// walls and trees inside the wedge; the scan descriptor summarises the full turn and cannot tell. The context is
// a polar grid of the labelled bird's-eye view (rings out to max_range_m, 128 sectors of 2.8 deg) with one bit
// per class group; two contexts are compared at every sector shift over the sectors the narrow one saw, which
// gives both a similarity and the heading between the two scans (as Scan Context does for full turns).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "sglc/background.hpp"
#include "sglc/config.hpp"
#include "sglc/fingerprint.hpp"

namespace sglc {

struct ViewContext {
  static constexpr int kSectors = 128;
  struct Row {  // one bit per sector: sector s is bit s % 64 of lo (s < 64) or hi
    std::uint64_t lo = 0, hi = 0;
  };
  std::vector<Row> building;    // per ring: sectors holding building or fence cells
  std::vector<Row> vegetation;  // per ring: sectors holding vegetation cells
  Row seen;                     // sectors where the view holds cells of any class (road too) in two rings or more
  // The structure classes came from the built-in labeller (Fingerprint::labeller_structure): building and
  // vegetation are compared as one class, as background agreement does for such scans.
  bool merged = false;
  int rings() const { return static_cast<int>(building.size()); }
  // Whether any building or vegetation lies in a sector it saw: without, every comparison with it gives 0.
  bool seesStructure() const;
  // The sectors it saw whose neighbours it also saw (one sector inside the edges of its view), one flag per
  // sector from -pi: the `field` bevAgreement judges a narrow view's agreement in.
  std::vector<bool> field() const;
};

// Whether a scan is a narrow view: it saw less than min_view_deg (VerifyConfig::background_min_view_deg) of the
// horizon (viewSpanDeg of its stored background).
bool isNarrowView(const Fingerprint& fp, double min_view_deg);

// The context of a labelled BEV (`cell` metres, BevCell positions) between 2 m and config.max_range_m, in
// config.rings rings.
ViewContext viewContext(const std::vector<BevCell>& cells, double cell, const ViewSearchConfig& config,
                        bool merged = false);

// viewContext of a fingerprint's background, kept with the fingerprint (Fingerprint::view_memo) for these
// settings: computed once however many queries compare with it. Thread-safe.
std::shared_ptr<const ViewContext> viewContextOf(const Fingerprint& fp, const ViewSearchConfig& config);

struct ViewMatch {
  // Of the grid cells in the sectors `narrow` saw where either context has structure, the share where both
  // have structure of one class group, at the best heading; 0 when nothing is compared.
  double similarity = 0;
  // The yaw (radians, [0, 2 pi)) turning `other`'s frame into `narrow`'s at that best shift (the rotation of
  // a T_narrow_other), to within a sector.
  double heading = 0;
};

// Compares a narrow view with others, at all 128 shifts over the sectors the narrow view saw; deterministic (the
// first best shift wins). The narrow view is turned once, on construction, for every comparison after.
class ViewMatcher {
 public:
  explicit ViewMatcher(const ViewContext& narrow);
  // `other` must have as many rings as the narrow view (throws InputError otherwise). Building and vegetation
  // are one class when either context is merged.
  ViewMatch match(const ViewContext& other) const;

 private:
  int rings_ = 0;
  bool merged_ = false;
  // The sectors the narrow view saw, and in each the rings holding building / vegetation (ring i is bit i).
  std::vector<int> seen_;
  std::vector<std::uint64_t> building_, vegetation_;
};

// ViewMatcher(narrow).match(other).
ViewMatch matchViews(const ViewContext& narrow, const ViewContext& other);

}  // namespace sglc
