#include "report.hpp"
#include "sglc/elapsed.hpp"

#include <algorithm>
#include <fstream>
#include <iomanip>
#include <stdexcept>

namespace sglc::eval {
void Timings::add(const StageTimes& t) {
  for (const auto& [name, v] : {std::pair{"fingerprint", t.fingerprint},
                                {"search", t.search},
                                {"verify", t.verify},
                                {"refine", t.refine},
                                {"store", t.store},
                                {"total", t.total}})
    stages_[name].push_back(v);
}

ordered_json Timings::json() const {
  ordered_json out;
  for (const auto& [name, v] : stages_)
    out[name] = {{"median_ms", percentile(v, 0.5)}, {"p90_ms", percentile(v, 0.9)}, {"n", v.size()}};
  return out;
}

void writeCurve(const std::string& path, const std::vector<PrPoint>& curve) {
  std::ofstream out(path);
  out << "threshold,precision,recall\n" << std::setprecision(9);
  for (const auto& p : curve) out << p.threshold << "," << p.precision << "," << p.recall << "\n";
  if (!out) throw std::runtime_error(path + ": write failed");
}

void curveSummary(ordered_json& summary, const std::vector<PrPoint>& curve) {
  const auto best = f1Max(curve);
  summary["f1max"] = best.f1;
  summary["f1max_threshold"] = best.threshold;
  summary["f1max_precision"] = best.precision;
  summary["f1max_recall"] = best.recall;
  summary["ep"] = extendedPrecision(curve);
  summary["auc"] = prAuc(curve);
}

void registrationSummary(ordered_json& summary, const std::vector<RegistrationResult>& results) {
  const auto r = registrationRecall(results);
  summary["rr"] = r.rr;
  summary["rr_verified"] = r.rr_verified;
  summary["registered"] = r.successes;
  summary["pose_pairs"] = r.pairs;
  summary["rte_mean"] = r.rte_mean;
  summary["rre_mean"] = r.rre_mean;
  summary["rte_median"] = r.rte_median;
  summary["rre_median"] = r.rre_median;
}

std::vector<PrPoint> detectionCurve(const std::vector<Decision>& decisions) {
  auto curve = prCurve(decisions);
  std::erase_if(curve, [](const PrPoint& p) { return p.threshold <= 0; });
  return curve;
}

}  // namespace sglc::eval
