// The loop decision (docs/METHOD.md, section 8): one model maps the evidence for a pose (sglc/evidence.hpp) to
// the probability that the loop is true: a logistic link over a sum of one monotone curve per fixed transform of
// the record (a monotone additive model; a curve is a weight times the value, or piecewise linear through
// knots and constant beyond them). The curves are fitted from simulated training worlds by tools/calibrate
// (reproducibly, from a command) and shipped as a small text file, core/models/loop_model.txt, built into the engine;
// verify.model names another. Monotone where physics says so: more landmarks, agreement, plane overlap or constraint
// never lowers p, a longer translation never raises it. A model file that breaks this is refused.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "sglc/evidence.hpp"

namespace sglc {

struct ModelFeature {
  const char* name;
  int sign;  // +1: its weight must be >= 0; -1: <= 0; 0: either
  const char* doc;
};

// The model's inputs, in order (the file names them; tools/calibrate reads the same list from sglc-eval's
// evidence.csv header).
const std::vector<ModelFeature>& modelFeatures();
// The feature values of a record, in modelFeatures() order.
std::vector<double> featureValues(const Evidence& e);

// One feature's term of the sum: slope x value, or, where knots are given, linear between them (x ascending)
// and constant beyond the first and the last.
struct FeatureCurve {
  double slope = 0.0;
  std::vector<std::pair<double, double>> knots;  // (value, term)
  double operator()(double x) const;
};

class LoopModel {
 public:
  // The built-in model (core/models/loop_model.txt at build time).
  static LoopModel builtIn();
  // Parses a model file's text; throws InputError naming the line and what is wrong (unknown or missing
  // feature, a number that is not finite or beyond +-1e6, knots out of order, or a curve whose direction breaks the
  // feature's monotonicity). A feature's line is "NAME WEIGHT" or "NAME X1:T1 X2:T2 ..." (at least 2 knots).
  static LoopModel parse(const std::string& text, const std::string& origin);
  // builtIn() for an empty path, else the file's model.
  static LoopModel load(const std::string& path);

  double probability(const Evidence& e) const;
  const std::string& version() const { return version_; }
  const std::vector<FeatureCurve>& curves() const { return curves_; }  // modelFeatures() order
  double bias() const { return bias_; }

 private:
  std::string version_;
  double bias_ = 0.0;
  std::vector<FeatureCurve> curves_;
};

}  // namespace sglc
