#include "loop_weight.hpp"

#include <algorithm>
#include <cmath>

namespace sglc::posegraph {

double loopLossFactor(std::optional<double> p, double trusted) {
  if (!p || !std::isfinite(*p) || trusted <= 0.0) return 1.0;  // unknown: as before the loop model
  const double q = std::clamp(*p, 1e-3, 1.0);
  if (q >= trusted) return 1.0;
  const double t = std::min(trusted, 1.0 - 1e-9);
  const double ratio = (q / (1.0 - q)) / (t / (1.0 - t));
  return std::sqrt(std::min(1.0, ratio));
}

}  // namespace sglc::posegraph
