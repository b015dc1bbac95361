// Background agreement of two fingerprints at a pose, on verification's grid: shared by the loop decision
// (verification.cpp) and the choice among known-loop poses (pipeline.cpp).
#pragma once

#include "sglc/background.hpp"
#include "sglc/config.hpp"
#include "sglc/fingerprint.hpp"

namespace sglc::detail {

// Building against vegetation is evidence only where neither scan's classes came from the built-in labeller.
inline double agreementAt(const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T,
                          const VerifyConfig& v) {
  const auto classes = query.labeller_structure || candidate.labeller_structure ? StructureClasses::kMerged
                                                                                : StructureClasses::kCompared;
  return bevAgreement(query.background, candidate.background, query.background_cell, T, v.bev_cell_m, v.bev_radius_m,
                      classes);
}

}  // namespace sglc::detail
