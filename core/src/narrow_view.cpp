#include "narrow_view.hpp"

#include <cmath>
#include <numbers>

#include "sglc/background.hpp"

namespace sglc::detail {

NarrowPair compareNarrow(const Fingerprint& query, const Fingerprint& candidate, bool query_narrow,
                         const ViewSearchConfig& config) {
  const Fingerprint& narrow = query_narrow ? query : candidate;
  const Fingerprint& other = query_narrow ? candidate : query;
  const auto n = viewContext(narrow.background, narrow.background_cell, config, narrow.labeller_structure);
  const auto o = viewContext(other.background, other.background_cell, config, other.labeller_structure);
  NarrowPair pair;
  pair.query_narrow = query_narrow;
  pair.match = matchViews(n, o);
  pair.field = n.field();
  return pair;
}

std::vector<double> viewHeadings(const NarrowPair& pair) {
  if (pair.match.similarity <= 0) return {};
  constexpr double kTurn = 2.0 * std::numbers::pi, kSector = kTurn / ViewContext::kSectors;
  const double h = pair.query_narrow ? pair.match.heading : kTurn - pair.match.heading;  // T_c_q's yaw turned round
  std::vector<double> headings;
  for (const double d : {-kSector, 0.0, kSector}) headings.push_back(std::fmod(h + d + 2.0 * kTurn, kTurn));
  return headings;
}

double viewAgreement(const NarrowPair& pair, const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T_q_c,
                     const ViewSearchConfig& config) {
  const auto classes = query.labeller_structure || candidate.labeller_structure ? StructureClasses::kMerged
                                                                                : StructureClasses::kCompared;
  // Judged in the narrow scan's frame, where its field is.
  if (pair.query_narrow)
    return bevAgreement(query.background, candidate.background, query.background_cell, T_q_c, config.agreement_cell_m,
                        config.max_range_m, classes, &pair.field);
  return bevAgreement(candidate.background, query.background, candidate.background_cell, T_q_c.inverse(),
                      config.agreement_cell_m, config.max_range_m, classes, &pair.field);
}

int landmarksAt(const Fingerprint& query, const Fingerprint& candidate, const Mat4d& T_q_c, double gate) {
  const Eigen::Matrix3f R = T_q_c.topLeftCorner<3, 3>().cast<float>();
  const Vec3f t = T_q_c.topRightCorner<3, 1>().cast<float>();
  std::vector<Vec3f> moved;
  moved.reserve(candidate.nodes.size());
  for (const auto& c : candidate.nodes) moved.push_back(R * c.center + t);
  // One to one: each query node takes the nearest free candidate node of its class within the gate, so one
  // pole cannot vouch twice.
  const float gate_sq = static_cast<float>(gate * gate);
  std::vector<bool> used(moved.size(), false);
  int n = 0;
  for (const auto& q : query.nodes) {
    int best = -1;
    float best_sq = gate_sq;
    for (std::size_t j = 0; j < moved.size(); ++j) {
      const float d = (moved[j] - q.center).head<2>().squaredNorm();
      if (!used[j] && candidate.nodes[j].cls == q.cls && d <= best_sq) {
        best = static_cast<int>(j);
        best_sq = d;
      }
    }
    if (best < 0) continue;
    used[static_cast<std::size_t>(best)] = true;
    ++n;
  }
  return n;
}

}  // namespace sglc::detail
