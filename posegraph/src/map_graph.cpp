#include "map_graph.hpp"

#include <ceres/ceres.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "relative_pose_error.hpp"
#include "sglc/log/log_line.hpp"
#include "sglc/rigid.hpp"

namespace sglc::posegraph {
namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;
constexpr double kWideLoss = 10.0;  // loss scale of the first solve, in nominal loss scales
// Whitened squared error of a discounted loop: the 99.9 % point of a chi-square with six degrees of freedom,
// in loss scales (the Cauchy weight there is below 0.05).
constexpr double kRejectChi2 = 22.46;

// Why a stored loop cannot be an edge, or nullopt.
std::optional<std::string> loopError(const storage::LoopRecord& l) {
  if (l.query_scan == l.candidate_scan) return std::string("joins a scan to itself");
  if (const auto error = rigidMotionError(l.T)) return "transform " + *error;
  if (l.information && !l.information->allFinite()) return std::string("information is not finite");
  if (!std::isfinite(l.rmse)) return std::string("rmse is not finite");
  return std::nullopt;
}

// The least-squares problem over the nodes' poses (per node: quaternion x, y, z, w, then translation).
struct Problem {
  ceres::Problem problem;
  std::vector<std::array<double, 7>> x;
  std::vector<RelativePoseError> loop_edges;
  std::vector<std::pair<std::size_t, std::size_t>> loop_nodes;
  std::vector<ceres::LossFunctionWrapper*> loop_losses;  // owned by the problem

  void addEdge(std::size_t a, std::size_t b, const RelativePoseError& e, ceres::LossFunction* loss) {
    problem.AddResidualBlock(relativePoseCost(e), loss, x[a].data(), x[b].data());
  }
  // Whitened residual of loop k at the current poses, squared.
  double loopError2(std::size_t k) {
    Eigen::Matrix<double, 6, 1> r;
    loop_edges[k](x[loop_nodes[k].first].data(), x[loop_nodes[k].second].data(), r.data());
    return r.squaredNorm();
  }
  void setLoopLoss(double scale) {
    for (auto* loss : loop_losses) loss->Reset(new ceres::CauchyLoss(scale), ceres::TAKE_OWNERSHIP);
  }
  // Ceres aborts the process on non-finite parameters: nothing non-finite goes in, and what comes out is checked.
  void requireFinite(const char* what) const {
    for (const auto& xi : x)
      for (double v : xi)
        if (!std::isfinite(v)) throw std::runtime_error(what);
  }
};

ceres::Solver::Options solverOptions(const GraphOptimiserOptions& o) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  so.max_num_iterations = o.max_iterations;
  so.max_solver_time_in_seconds = o.max_seconds;
  so.num_threads = 1;  // deterministic
  so.logging_type = ceres::SILENT;
  return so;
}

// Checks the problem is finite (Ceres aborts the process otherwise), then solves it: with a wide loop loss
// first when `wide`, then the nominal one.
MapGraph::Solution runSolver(Problem& p, const GraphOptimiserOptions& options, bool wide, bool empty) {
  p.requireFinite("a node's initial pose is not finite");
  if (!empty) {
    double cost = 0;
    if (!p.problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr) ||
        !std::isfinite(cost))
      throw std::runtime_error("the graph's initial cost is not finite");
  }
  MapGraph::Solution solution;
  solution.converged = empty;  // nothing to solve is solved
  if (!empty) {
    const auto so = solverOptions(options);
    if (wide) {
      ceres::Solver::Summary first;
      p.setLoopLoss(kWideLoss * options.loss_scale);
      ceres::Solve(so, &p.problem, &first);
      p.setLoopLoss(options.loss_scale);
      solution.iterations += first.iterations.size();
    }
    ceres::Solver::Summary last;
    ceres::Solve(so, &p.problem, &last);
    if (!last.IsSolutionUsable()) throw std::runtime_error("the solver failed: " + last.message);
    solution.converged = last.termination_type == ceres::CONVERGENCE;
    solution.iterations += last.iterations.size();
  }
  return solution;
}

}  // namespace

Pose Pose::of(const Mat4d& T) {
  Pose p;
  p.q = Eigen::Quaterniond(T.block<3, 3>(0, 0)).normalized();
  p.t = T.block<3, 1>(0, 3);
  return p;
}

Mat4d Pose::matrix() const {
  Mat4d T = Mat4d::Identity();
  T.block<3, 3>(0, 0) = q.normalized().toRotationMatrix();
  T.block<3, 1>(0, 3) = t;
  return T;
}

bool MapGraph::absorb(const std::string& map, const std::vector<storage::LoopRecord>& loops,
                      const std::vector<storage::GraphNodeRecord>& nodes,
                      const std::unordered_map<std::int64_t, Mat4d>& kept) {
  bool changed = false;
  for (const auto& n : nodes) {
    last_scan_ = std::max(last_scan_, n.scan_id);
    if (!n.odometry_pose) continue;
    // Files written before the server checked poses may hold ones that are not rigid motions: such a scan is
    // no graph node (a pose graph cannot use it), but it stays in the map.
    if (const auto error = rigidMotionError(*n.odometry_pose)) {
      spdlog::warn("{}", logging::logLine({{"event", "graph_node_skipped"},
                                           {"map", map},
                                           {"scan", n.scan_id},
                                           {"error", "odometry pose " + *error}}));
      continue;
    }
    changed = true;
    index_[n.scan_id] = nodes_.size();
    const auto k = kept.find(n.scan_id);
    const Mat4d odometry = orthonormalised(*n.odometry_pose);
    nodes_.push_back(
        {n.scan_id, n.session_id, n.seq, odometry, Pose::of(k != kept.end() ? k->second : odometry), k != kept.end()});
    map_session_ = map_session_ < 0 ? n.session_id : std::min(map_session_, n.session_id);
  }
  for (const auto& l : loops) {
    last_loop_ = std::max(last_loop_, l.id);
    if (!index_.count(l.query_scan) || !index_.count(l.candidate_scan)) continue;
    if (const auto error = loopError(l)) {
      spdlog::warn(
          "{}", logging::logLine({{"event", "graph_loop_skipped"}, {"map", map}, {"loop", l.id}, {"error", *error}}));
      continue;
    }
    // A second loop for the same pair replaced the first in the database: drop the first here too.
    if (!pairs_.insert({l.query_scan, l.candidate_scan}).second)
      loops_.erase(std::find_if(loops_.begin(), loops_.end(),
                                [&](const auto& o) { return o.a == l.query_scan && o.b == l.candidate_scan; }));
    loops_.push_back({l.id, l.query_scan, l.candidate_scan, orthonormalised(l.T), l.rmse, l.information});
    changed = true;
  }
  return changed;
}

std::int64_t MapGraph::root(std::int64_t s) {
  while (parent_[s] != s) s = parent_[s] = parent_[parent_[s]];
  return s;
}

// Sessions and their scans in sequence order; components: sessions linked by loops (union-find), the smaller
// session id the root.
void MapGraph::layout() {
  sessions_.clear();
  parent_.clear();
  for (std::size_t i = 0; i < nodes_.size(); ++i) sessions_[nodes_[i].session_id].push_back(i);
  for (auto& [sid, idx] : sessions_)
    std::stable_sort(idx.begin(), idx.end(),
                     [&](std::size_t a, std::size_t b) { return nodes_[a].seq < nodes_[b].seq; });
  for (const auto& [sid, idx] : sessions_) parent_[sid] = sid;
  for (const auto& l : loops_) {
    const auto a = root(nodes_[index_[l.a]].session_id), b = root(nodes_[index_[l.b]].session_id);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }
}

// Places the session's uninitialised nodes: chained from the previous initialised node of the session, else
// by the session frame.
void MapGraph::initialiseSession(std::int64_t sid, const Mat4d& T_frame) {
  const auto& idx = sessions_[sid];
  for (std::size_t k = 0; k < idx.size(); ++k) {
    auto& n = nodes_[idx[k]];
    if (n.initialised) continue;
    if (k > 0 && nodes_[idx[k - 1]].initialised) {
      const auto& prev = nodes_[idx[k - 1]];
      n.pose = Pose::of(prev.pose.matrix() * prev.odometry.inverse() * n.odometry);
    } else {
      n.pose = Pose::of(T_frame * n.odometry);
    }
    n.initialised = true;
  }
}

// Initial guesses: the map session and each component's root in their own odometry frames; other sessions
// through their first loop to a placed session; what remains in its own frame.
void MapGraph::initialise() {
  std::set<std::int64_t> placed;
  for (const auto& [sid, idx] : sessions_) {
    const bool any = std::any_of(idx.begin(), idx.end(), [&](std::size_t i) { return nodes_[i].initialised; });
    if (any || root(sid) == sid) {
      const auto& first = nodes_[idx.front()];
      initialiseSession(sid, any ? Mat4d(first.pose.matrix() * first.odometry.inverse()) : Mat4d::Identity());
      placed.insert(sid);
    }
  }
  for (bool progress = true; progress;) {
    progress = false;
    for (const auto& l : loops_) {
      const auto& na = nodes_[index_[l.a]];
      const auto& nb = nodes_[index_[l.b]];
      const bool pa = placed.count(na.session_id), pb = placed.count(nb.session_id);
      if (pa == pb) continue;
      // T_map_b = T_map_a * T_ab (or the inverse way round); the unplaced session's frame follows.
      if (pa) {
        const Mat4d T_map_b = na.pose.matrix() * l.T;
        initialiseSession(nb.session_id, T_map_b * nb.odometry.inverse());
        placed.insert(nb.session_id);
      } else {
        const Mat4d T_map_a = nb.pose.matrix() * l.T.inverse();
        initialiseSession(na.session_id, T_map_a * na.odometry.inverse());
        placed.insert(na.session_id);
      }
      progress = true;
    }
  }
  for (const auto& [sid, idx] : sessions_) initialiseSession(sid, Mat4d::Identity());
}

MapGraph::Solution MapGraph::solve(const GraphOptimiserOptions& options, std::int64_t solved_through) {
  layout();
  initialise();
  Problem p;
  p.x.resize(nodes_.size());
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const auto& pose = nodes_[i].pose;
    p.x[i] = {pose.q.x(), pose.q.y(), pose.q.z(), pose.q.w(), pose.t.x(), pose.t.y(), pose.t.z()};
  }
  // Odometry: trusted (no robust loss), sigmas growing with the distance driven.
  for (const auto& [sid, idx] : sessions_)
    for (std::size_t k = 1; k < idx.size(); ++k) {
      const Mat4d step = nodes_[idx[k - 1]].odometry.inverse() * nodes_[idx[k]].odometry;
      const double d = step.block<3, 1>(0, 3).norm();
      p.addEdge(idx[k - 1], idx[k],
                relativePoseError(
                    step, diagonalSqrtInformation(
                              options.odometry_sigma_m + options.odometry_sigma_per_m * d,
                              (options.odometry_sigma_deg + options.odometry_sigma_deg_per_m * d) * kRadPerDeg)),
                nullptr);
    }
  // Loops: the registration's information plus a floor covariance, or (loops recorded without one) a sigma from
  // the refinement's residual; a robust loss discounts false ones.
  const double floor_r = options.loop_sigma_deg * kRadPerDeg;
  for (const auto& l : loops_) {
    if (l.information) {
      p.loop_edges.push_back(
          relativePoseError(l.T, loopSqrtInformation(*l.information, options.loop_sigma_m, floor_r)));
    } else {
      const double st = std::max(options.loop_sigma_m, l.rmse);
      p.loop_edges.push_back(relativePoseError(l.T, diagonalSqrtInformation(st, floor_r * st / options.loop_sigma_m)));
    }
    p.loop_nodes.emplace_back(index_[l.a], index_[l.b]);
    p.loop_losses.push_back(
        new ceres::LossFunctionWrapper(new ceres::CauchyLoss(options.loss_scale), ceres::TAKE_OWNERSHIP));
    p.addEdge(index_[l.a], index_[l.b], p.loop_edges.back(), p.loop_losses.back());
  }
  // Graduated: when a new loop is far off the current poses (a first optimisation from odometry, a long drift
  // corrected at once), a tight Cauchy loss would discount it along with false ones: solve with a wide loss
  // first, then the nominal one. Loops that agree with the warm-started graph need only the second solve.
  bool wide = false;
  for (std::size_t k = 0; k < loops_.size() && !wide; ++k)
    wide = loops_[k].id > solved_through && p.loopError2(k) > std::pow(kWideLoss * options.loss_scale, 2);
  for (auto& xi : p.x)
    p.problem.AddParameterBlock(
        xi.data(), 7, new ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>());
  // The root session's first node anchors its component (the map frame for the map session's).
  std::set<std::int64_t> fixed_roots;
  for (const auto& [sid, idx] : sessions_)
    if (fixed_roots.insert(root(sid)).second)
      p.problem.SetParameterBlockConstant(p.x[sessions_[root(sid)].front()].data());

  auto out = runSolver(p, options, wide, nodes_.empty());
  p.requireFinite("the solution is not finite");
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    nodes_[i].pose.q = Eigen::Quaterniond(p.x[i][3], p.x[i][0], p.x[i][1], p.x[i][2]).normalized();
    nodes_[i].pose.t = Eigen::Vector3d(p.x[i][4], p.x[i][5], p.x[i][6]);
  }
  for (std::size_t k = 0; k < loops_.size(); ++k)
    out.rejected_loops += p.loopError2(k) > kRejectChi2 * options.loss_scale * options.loss_scale;
  converged_ = out.converged;
  return out;
}

std::vector<storage::OptimisedPose> MapGraph::poses() const {
  std::vector<storage::OptimisedPose> out;
  for (const auto& n : nodes_) out.push_back({n.scan_id, n.pose.matrix()});
  return out;
}

std::vector<storage::SessionFrame> MapGraph::frames() {
  std::vector<storage::SessionFrame> out;
  const auto map_root = map_session_ < 0 ? -1 : root(map_session_);
  for (const auto& [sid, idx] : sessions_) {
    const auto& first = nodes_[idx.front()];
    storage::SessionFrame f;
    f.session_id = sid;
    f.connected = root(sid) == map_root;
    f.T_map_session = f.connected ? Mat4d(first.pose.matrix() * first.odometry.inverse()) : Mat4d::Identity();
    out.push_back(f);
  }
  return out;
}

}  // namespace sglc::posegraph
