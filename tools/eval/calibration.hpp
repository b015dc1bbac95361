// What the loop model's probability means, measured: every hypothesis verification judged, with whether its
// pose is true, goes to evidence.csv (the training rows of tools/calibrate); each candidate's answer (the
// hypothesis it was judged by) counts in a reliability table (predicted against observed share of true loops in
// 10 bins of the probability) and the expected calibration error, ECE = sum over bins of the share of answers
// in the bin x |mean predicted - observed|. A pose is true when it lies within 2 m and 5 deg of the ground truth
// (the RR definition of the pose protocol).
#pragma once

#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "backend.hpp"
#include "report.hpp"

namespace sglc::eval {

inline constexpr double kTrueRteM = 2.0, kTrueRreDeg = 5.0;

class CalibrationLog {
 public:
  explicit CalibrationLog(const std::string& evidence_csv);
  // One candidate of query frame `query`; ground_truth is its T_q_c (null: unknown, not counted).
  void add(int query, const Candidate& candidate, const Mat4d* ground_truth);
  // A candidate known to be no loop (a listed negative pair): every hypothesis is false.
  void addFalse(int query, const Candidate& candidate);
  // "calibration": answers, true answers, ECE and the 10 bins; also writes calibration.csv beside evidence.csv.
  void summarise(ordered_json& summary) const;

 private:
  struct Bin {
    std::size_t n = 0, positives = 0;
    double predicted = 0;
  };
  void row(int query, const Candidate& c, const LoopResult::Judged& h, bool chosen, bool is_true, double rte_m,
           double rre_deg);
  std::string dir_;
  std::ofstream csv_;
  Bin bins_[10];
};

}  // namespace sglc::eval
