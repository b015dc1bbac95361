#include "calibration.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>

#include "metrics.hpp"
#include "sglc/loop_model.hpp"

namespace sglc::eval {

CalibrationLog::CalibrationLog(const std::string& evidence_csv)
    : dir_(evidence_csv.substr(0, evidence_csv.find_last_of('/') + 1)), csv_(evidence_csv) {
  csv_ << "query,candidate,source,chosen,probability,true,rte_m,rre_deg,landmarks,landmark_similarity,field_deg,"
          "agreement,wide_agreement,pin,plane_overlap,plane_rmse_m,constraint,context_similarity,translation_m,narrow";
  for (const auto& f : modelFeatures()) csv_ << ",x" << (f.sign > 0 ? '+' : f.sign < 0 ? '-' : '~') << f.name;
  csv_ << "\n" << std::setprecision(7);
}

void CalibrationLog::add(int query, const Candidate& c, const Mat4d* gt) {
  if (!gt) return;
  bool chosen_done = false;
  for (const auto& h : c.considered) {
    const auto err = poseError(h.T, *gt);
    // The answer: the first hypothesis with the candidate's probability.
    const bool chosen = !chosen_done && h.probability == c.probability;
    chosen_done = chosen_done || chosen;
    row(query, c, h, chosen, err.rte_m < kTrueRteM && err.rre_deg < kTrueRreDeg, err.rte_m, err.rre_deg);
  }
}

void CalibrationLog::addFalse(int query, const Candidate& c) {
  bool chosen_done = false;
  for (const auto& h : c.considered) {
    const bool chosen = !chosen_done && h.probability == c.probability;
    chosen_done = chosen_done || chosen;
    row(query, c, h, chosen, false, std::nan(""), std::nan(""));
  }
}

void CalibrationLog::row(int query, const Candidate& c, const LoopResult::Judged& h, bool chosen, bool is_true,
                         double rte_m, double rre_deg) {
  const auto& e = h.evidence;
  csv_ << query << "," << c.frame << "," << poseSourceName(e.source) << "," << int(chosen) << "," << h.probability
       << "," << int(is_true) << "," << rte_m << "," << rre_deg << "," << e.landmarks << "," << e.landmark_similarity
       << "," << e.field_deg << "," << e.agreement << "," << e.wide_agreement << "," << e.pin << "," << e.plane_overlap
       << "," << e.plane_rmse_m << "," << e.constraint << "," << e.context_similarity << "," << e.translation_m << ","
       << int(e.narrow);
  for (const double x : featureValues(e)) csv_ << "," << x;
  csv_ << "\n";
  if (!chosen) return;
  auto& b = bins_[std::min(9, static_cast<int>(h.probability * 10.0))];
  ++b.n;
  b.positives += is_true;
  b.predicted += h.probability;
}

void CalibrationLog::summarise(ordered_json& summary) const {
  std::size_t n = 0, positives = 0;
  for (const auto& b : bins_) {
    n += b.n;
    positives += b.positives;
  }
  std::ofstream out(dir_ + "calibration.csv");
  out << "bin_low,bin_high,answers,mean_predicted,observed_true\n" << std::setprecision(6);
  ordered_json bins = ordered_json::array();
  double ece = 0.0;
  for (int k = 0; k < 10; ++k) {
    const auto& b = bins_[k];
    const double predicted = b.n ? b.predicted / static_cast<double>(b.n) : 0.0;
    const double observed = b.n ? static_cast<double>(b.positives) / static_cast<double>(b.n) : 0.0;
    if (n) ece += static_cast<double>(b.n) / static_cast<double>(n) * std::abs(predicted - observed);
    out << k / 10.0 << "," << (k + 1) / 10.0 << "," << b.n << "," << predicted << "," << observed << "\n";
    bins.push_back({{"low", k / 10.0}, {"answers", b.n}, {"mean_predicted", predicted}, {"observed_true", observed}});
  }
  summary["calibration"] = {{"answers", n},
                            {"true_answers", positives},
                            {"ece", n ? ece : 0.0},
                            {"bins", bins},
                            {"true_pose", "RTE < 2 m and RRE < 5 deg"}};
}

}  // namespace sglc::eval
