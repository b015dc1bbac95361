// How much a loop's probability of being true (the loop model's, sglc::LoopResult::probability) lets it pull
// on the pose graph: a factor on its Cauchy loss scale.
#pragma once

#include <optional>

namespace sglc::posegraph {

// The factor on pose_graph.loss_scale for a loop of probability `p` (nullopt: unknown, recorded before the loop
// model: 1, as before). A Cauchy loss of scale c pulls a residual far off (whitened squared error s >> c^2)
// with the weight c^2 / s: like a posterior odds ratio, prior odds times the likelihood ratio of the residual.
// The loop's prior odds p / (1 - p) therefore scale c^2, relative to those of `trusted` (the probability at
// which a loop counts as much as every loop did before the model): factor^2 = min(1, odds(p) / odds(trusted)).
// A probability never widens the loss beyond the configured scale, so it cannot make a false loop with a
// confident model worse than the robust loss alone. p is clamped to [1e-3, 1] first (p = 0 still keeps a tiny
// scale: a Cauchy loss needs one above 0).
double loopLossFactor(std::optional<double> p, double trusted);

}  // namespace sglc::posegraph
