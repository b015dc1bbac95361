// A background-only loop where one scan is a narrow view (docs/METHOD.md, section 8): the narrow scan's view
// context against the other's gives the headings to search and the view's own field, and the pose found is
// judged on that field (config.view_search). Private to verification.cpp.
#pragma once

#include <vector>

#include "sglc/config.hpp"
#include "sglc/fingerprint.hpp"
#include "sglc/view_context.hpp"

namespace sglc::detail {

struct NarrowPair {
  bool query_narrow = true;  // else the candidate is the narrow one
  ViewMatch match;           // of the narrow scan's context over the other's
  std::vector<bool> field;   // the narrow scan's context's field (ViewContext::field)
};

// Compares the narrow scan's context with the other's.
NarrowPair compareNarrow(const Fingerprint& query, const Fingerprint& candidate, bool query_narrow,
                         const ViewSearchConfig& config);

// Headings (T_q_c's yaw, radians) to search: the context's best shift and a sector either side. Empty when the
// contexts share nothing.
std::vector<double> viewHeadings(const NarrowPair& pair);

// Background agreement of the pair at T_q_c over the narrow scan's field, out to config.max_range_m on a
// config.agreement_cell_m grid.
double viewAgreement(const NarrowPair& pair, const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T_q_c,
                     const ViewSearchConfig& config);

// Query landmarks (nodes) paired one to one with a candidate node of their class within `gate` metres on the
// ground under T_q_c.
int landmarksAt(const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T_q_c, double gate);

}  // namespace sglc::detail
