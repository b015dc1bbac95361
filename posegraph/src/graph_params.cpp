#include "sglc/posegraph/graph_optimiser.hpp"

namespace sglc::posegraph {
namespace {

using namespace params;
using Options = GraphOptimiserOptions;

#define SGLC_KEY(name) \
#name, [](auto& o) -> auto& { return o.name; }

Table<Options> makeTable() {
  Table<Options> t;
  t.add(duration<Options>(
      "debounce_ms", [](auto& o) -> auto& { return o.debounce; }, 1, closed(0, 60000),
      "wait this long after a loop for more before optimising (ms)"));
  t.add(field<Options>(SGLC_KEY(max_seconds), above(0), "time limit of one optimisation (s)"));
  t.add(field<Options>(SGLC_KEY(max_iterations), closed(1, 100000), "solver iterations per optimisation"));
  t.add(field<Options>(SGLC_KEY(max_continuations), closed(0, 1000),
                       "solves that go on from an unconverged one without new scans or loops"));
  t.add(field<Options>(SGLC_KEY(loss_scale), above(0), "Cauchy loss scale on whitened loop residuals"));
  t.add(field<Options>(SGLC_KEY(trusted_probability), closed(0, 1),
                       "loops less probable than this get a narrower loss (scale^2 x their odds over its odds); 0: "
                       "the probability is not used"));
  t.add(field<Options>(SGLC_KEY(local_window), closed(0, 100000),
                       "per loop event, free only this many nodes either side of each new loop's ends (0: global)"));
  t.add(field<Options>(SGLC_KEY(global_interval_s), closed(0, 86400),
                       "after a local solve, solve the whole graph within this many seconds"));
  t.add(field<Options>(SGLC_KEY(replica_poll_s), closed(0.05, 3600),
                       "servers sharing a PostgreSQL map: how often each looks for the others' loops and takes over "
                       "maps whose solving server died (s)"));
  t.add(field<Options>(SGLC_KEY(odometry_sigma_m), atLeast(0), "odometry: per-axis sigma per step (m)"));
  t.add(field<Options>(SGLC_KEY(odometry_sigma_per_m), atLeast(0), "odometry: added per metre driven (m/m)"));
  t.add(field<Options>(SGLC_KEY(odometry_sigma_deg), atLeast(0), "odometry: per-axis sigma per step (deg)"));
  t.add(field<Options>(SGLC_KEY(odometry_sigma_deg_per_m), atLeast(0), "odometry: added per metre driven (deg/m)"));
  t.add(field<Options>(SGLC_KEY(loop_sigma_m), above(0), "loops: per-axis floor sigma (m)"));
  t.add(field<Options>(SGLC_KEY(loop_sigma_deg), above(0), "loops: per-axis floor sigma (deg)"));
  t.rule({"odometry_sigma_m", "odometry_sigma_per_m"}, "> 0 in sum",
         [](const Options& o) { return o.odometry_sigma_m + o.odometry_sigma_per_m > 0; });
  t.rule({"odometry_sigma_deg", "odometry_sigma_deg_per_m"}, "> 0 in sum",
         [](const Options& o) { return o.odometry_sigma_deg + o.odometry_sigma_deg_per_m > 0; });
  return t;
}

#undef SGLC_KEY

}  // namespace

const params::Table<GraphOptimiserOptions>& graphParams() {
  static const params::Table<GraphOptimiserOptions> table = makeTable();
  return table;
}

}  // namespace sglc::posegraph
