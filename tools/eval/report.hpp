// What one protocol run writes: stage timings (medians and p90), the precision-recall curve as CSV, and the
// curve's and the registrations' summary figures into summary.json.
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "backend.hpp"
#include "metrics.hpp"

namespace sglc::eval {

using nlohmann::ordered_json;

// Per-stage times of every frame or call, summarised as median, p90 and count per stage.
class Timings {
 public:
  void add(const StageTimes& t);
  ordered_json json() const;

 private:
  std::map<std::string, std::vector<double>> stages_;
};

// threshold,precision,recall per point.
void writeCurve(const std::string& path, const std::vector<PrPoint>& curve);
// f1max (with its threshold, precision and recall), ep, auc.
void curveSummary(ordered_json& summary, const std::vector<PrPoint>& curve);
// rr, rr_verified, registered, pose_pairs, rte/rre mean and median.
void registrationSummary(ordered_json& summary, const std::vector<RegistrationResult>& results);

// The PR curve of detections. Detections that fail verification carry score 0: they are never a detection, so
// the curve's point at a threshold of 0 (where they would all count) is left out.
std::vector<PrPoint> detectionCurve(const std::vector<Decision>& decisions);

}  // namespace sglc::eval
