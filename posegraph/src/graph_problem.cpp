#include "graph_problem.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace sglc::posegraph {

void GraphProblem::addEdge(std::size_t a, std::size_t b, const RelativePoseError& e, ceres::LossFunction* loss) {
  problem.AddResidualBlock(relativePoseCost(e), loss, x[a].data(), x[b].data());
}

void GraphProblem::addLoopEdge(std::size_t loop_index, std::size_t a, std::size_t b, const RelativePoseError& e,
                               double loss_scale, double loss_factor) {
  loop.push_back(loop_index);
  loop_edges.push_back({a, b, e});
  loop_loss_factors.push_back(loss_factor);
  loop_losses.push_back(
      new ceres::LossFunctionWrapper(new ceres::CauchyLoss(loss_scale * loss_factor), ceres::TAKE_OWNERSHIP));
  addEdge(a, b, e, loop_losses.back());
}

double GraphProblem::maxBoundaryError2() const {
  double m = 0;
  for (const auto& e : boundary_edges) m = std::max(m, error2(e));
  return m;
}

void GraphProblem::setLoopLoss(double scale) {
  for (std::size_t k = 0; k < loop_losses.size(); ++k)
    loop_losses[k]->Reset(new ceres::CauchyLoss(scale * loop_loss_factors[k]), ceres::TAKE_OWNERSHIP);
}

void GraphProblem::requireFinite(const char* what) const {
  for (const auto& xi : x)
    for (double v : xi)
      if (!std::isfinite(v)) throw std::runtime_error(what);
}

namespace {

ceres::Solver::Options solverOptions(const GraphOptimiserOptions& o) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  so.max_num_iterations = o.max_iterations;
  so.max_solver_time_in_seconds = o.max_seconds;
  so.num_threads = 1;  // deterministic
  so.logging_type = ceres::SILENT;
  return so;
}

// Stops the solver when the flag is set.
class Cancel : public ceres::IterationCallback {
 public:
  explicit Cancel(const std::atomic<bool>* flag) : flag_(flag) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary&) override {
    return flag_ != nullptr && flag_->load() ? ceres::SOLVER_ABORT : ceres::SOLVER_CONTINUE;
  }

 private:
  const std::atomic<bool>* flag_;
};

}  // namespace

SolverRun runSolver(GraphProblem& p, const GraphOptimiserOptions& options, bool wide, double wide_scale,
                    const std::atomic<bool>* cancel) {
  p.requireFinite("a node's initial pose is not finite");
  const bool empty = p.problem.NumResidualBlocks() == 0;
  if (!empty) {
    double cost = 0;
    if (!p.problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr) ||
        !std::isfinite(cost))
      throw std::runtime_error("the graph's initial cost is not finite");
  }
  SolverRun run;
  run.converged = empty;  // nothing to solve is solved
  if (empty) return run;
  auto so = solverOptions(options);
  Cancel stop(cancel);
  so.callbacks.push_back(&stop);
  if (wide) {
    ceres::Solver::Summary first;
    p.setLoopLoss(wide_scale);
    ceres::Solve(so, &p.problem, &first);
    p.setLoopLoss(options.loss_scale);
    run.iterations += first.iterations.size();
  }
  ceres::Solver::Summary last;
  ceres::Solve(so, &p.problem, &last);
  if (!last.IsSolutionUsable()) throw std::runtime_error("the solver failed: " + last.message);
  run.converged = last.termination_type == ceres::CONVERGENCE;
  run.iterations += last.iterations.size();
  p.requireFinite("the solution is not finite");
  return run;
}

}  // namespace sglc::posegraph
