// The least-squares problem of one solve over part or all of a map's pose graph, and the solver run on it.
// MapGraph decides which nodes are free (map_graph.hpp); this holds their parameters, the edges touching them
// and the nodes those edges reach (held constant), and runs Ceres with the checks that keep it from aborting.
#pragma once

#include <ceres/ceres.h>

#include <array>
#include <atomic>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "relative_pose_error.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"

namespace sglc::posegraph {

struct GraphProblem {
  // An edge between two slots, kept to read its error after the solve.
  struct Edge {
    std::size_t a, b;
    RelativePoseError error;
  };
  ceres::Problem problem;
  std::vector<std::size_t> node;         // slot -> graph node index
  std::vector<std::array<double, 7>> x;  // per slot: quaternion x, y, z, w, then translation
  std::vector<std::size_t> loop;         // loop edge -> index into the graph's loops
  std::vector<Edge> loop_edges;
  std::vector<ceres::LossFunctionWrapper*> loop_losses;  // owned by the problem
  std::vector<double> loop_loss_factors;                 // per loop edge: its factor on every loss scale
  // Odometry edges between a free and a fixed node (a local solve's boundary): their whitened error tells
  // whether the window could absorb what is new.
  std::vector<Edge> boundary_edges;

  void addEdge(std::size_t slot_a, std::size_t slot_b, const RelativePoseError& e, ceres::LossFunction* loss);
  // The loop's robust loss is a Cauchy loss of scale `loss_scale` x `loss_factor` (loopLossFactor), in the
  // nominal and the wide solve alike.
  void addLoopEdge(std::size_t loop_index, std::size_t slot_a, std::size_t slot_b, const RelativePoseError& e,
                   double loss_scale, double loss_factor);
  // Whitened error of an edge at the current parameters, squared.
  double error2(const Edge& e) const { return e.error.squaredError(x[e.a].data(), x[e.b].data()); }
  // The largest of the boundary edges' (0 without any).
  double maxBoundaryError2() const;
  void setLoopLoss(double scale);  // every loop edge's Cauchy scale to scale x its factor
  // Ceres aborts the process on non-finite parameters: nothing non-finite goes in, and what comes out is checked.
  void requireFinite(const char* what) const;
};

struct SolverRun {
  bool converged = false;
  std::size_t iterations = 0;
};

// Checks the problem is finite, then solves it: with a wide loop loss (`wide_scale`) first when `wide`, then
// the nominal one. A set `cancel` aborts at the next iteration. Throws std::runtime_error on non-finite input, a
// failed or an aborted solve.
SolverRun runSolver(GraphProblem& p, const GraphOptimiserOptions& options, bool wide, double wide_scale,
                    const std::atomic<bool>* cancel = nullptr);

}  // namespace sglc::posegraph
