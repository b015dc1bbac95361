#include "map_graph.hpp"

#include <ceres/ceres.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "graph_problem.hpp"
#include "loop_weight.hpp"
#include "relative_pose_error.hpp"
#include "sglc/log/log_line.hpp"
#include "sglc/rigid.hpp"

namespace sglc::posegraph {
namespace {

constexpr double kWideLoss = 10.0;  // loss scale of the first solve, in nominal loss scales
// Whitened squared error of a discounted loop: the 99.9 % point of a chi-square with six degrees of freedom,
// in loss scales (the Cauchy weight there is below 0.05).
constexpr double kRejectChi2 = 22.46;

// The solver's parameters of a pose.
std::array<double, 7> parameters(const Pose& pose) {
  return {pose.q.x(), pose.q.y(), pose.q.z(), pose.q.w(), pose.t.x(), pose.t.y(), pose.t.z()};
}

// The loop's edge: the registration's information plus a floor covariance, or (loops recorded without one) a
// sigma from the refinement's residual.
RelativePoseError loopEdge(const MapGraph::Loop& l, const GraphOptimiserOptions& options) {
  return relativePoseError(
      l.T, loopEdgeSqrtInformation(l.information, l.rmse, options.loop_sigma_m, options.loop_sigma_deg));
}

}  // namespace

std::optional<std::string> loopError(const storage::LoopRecord& l) {
  if (l.query_scan == l.candidate_scan) return std::string("joins a scan to itself");
  if (const auto error = rigidMotionError(l.T)) return "transform " + *error;
  if (l.information && !l.information->allFinite()) return std::string("information is not finite");
  if (!std::isfinite(l.rmse)) return std::string("rmse is not finite");
  return std::nullopt;
}

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
    loops_.push_back(
        {l.id, l.query_scan, l.candidate_scan, orthonormalised(l.T), l.rmse, l.information, l.probability});
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
  position_.assign(nodes_.size(), 0);
  for (auto& [sid, idx] : sessions_) {
    std::stable_sort(idx.begin(), idx.end(),
                     [&](std::size_t a, std::size_t b) { return nodes_[a].seq < nodes_[b].seq; });
    for (std::size_t k = 0; k < idx.size(); ++k) position_[idx[k]] = k;
  }
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
    // The session's frame from a node already placed (not necessarily its first: a scan of lower sequence
    // number can arrive late), else its own odometry frame when it roots its component.
    const auto placed_node = std::find_if(idx.begin(), idx.end(), [&](std::size_t i) { return nodes_[i].initialised; });
    if (placed_node != idx.end() || root(sid) == sid) {
      const auto frame = placed_node == idx.end()
                             ? Mat4d::Identity()
                             : Mat4d(nodes_[*placed_node].pose.matrix() * nodes_[*placed_node].odometry.inverse());
      initialiseSession(sid, frame);
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

bool MapGraph::newLoopFarOff(const GraphOptimiserOptions& options, std::int64_t solved_through) const {
  const double limit = std::pow(kWideLoss * options.loss_scale, 2);
  for (const auto& l : loops_) {
    if (l.id <= solved_through) continue;
    const auto a = parameters(nodes_[index_.at(l.a)].pose), b = parameters(nodes_[index_.at(l.b)].pose);
    const double e2 = loopEdge(l, options).squaredError(a.data(), b.data());
    if (!std::isfinite(e2) || e2 > limit) return true;
  }
  return false;
}

std::vector<char> MapGraph::localScope(const GraphOptimiserOptions& options, std::int64_t solved_through) const {
  std::vector<char> free(nodes_.size(), 0);
  std::size_t count = 0;
  const auto mark = [&](std::size_t i) {
    count += !free[i];
    free[i] = 1;
  };
  for (std::size_t i = solved_nodes_; i < nodes_.size(); ++i) mark(i);
  const auto w = static_cast<std::size_t>(options.local_window);
  for (const auto& l : loops_) {
    if (l.id <= solved_through) continue;
    for (const auto scan : {l.a, l.b}) {
      const auto i = index_.at(scan);
      const auto& idx = sessions_.at(nodes_[i].session_id);
      const auto p = position_[i];
      for (std::size_t k = p > w ? p - w : 0; k <= std::min(idx.size() - 1, p + w); ++k) mark(idx[k]);
    }
  }
  // Nothing new after a local solve stopped at its bound: go on with the same nodes.
  if (count == 0 && !converged_ && last_free_.size() == nodes_.size()) return last_free_;
  if (count == 0 || 2 * count > nodes_.size()) return {};
  return free;
}

void MapGraph::buildProblem(GraphProblem& p, const GraphOptimiserOptions& options, const std::vector<char>& free) {
  const bool all = free.empty();
  const auto isFree = [&](std::size_t i) { return all || free[i] != 0; };
  // Slots: the free nodes and every node an edge of theirs reaches.
  constexpr auto kNone = static_cast<std::size_t>(-1);
  std::vector<std::size_t> slot(nodes_.size(), kNone);
  const auto use = [&](std::size_t i) {
    if (slot[i] == kNone) {
      slot[i] = p.node.size();
      p.node.push_back(i);
    }
  };
  std::vector<std::pair<std::size_t, std::size_t>> odometry;
  for (const auto& [sid, idx] : sessions_)
    for (std::size_t k = 1; k < idx.size(); ++k)
      if (isFree(idx[k - 1]) || isFree(idx[k])) odometry.emplace_back(idx[k - 1], idx[k]);
  std::vector<std::size_t> loops;
  for (std::size_t k = 0; k < loops_.size(); ++k)
    if (isFree(index_[loops_[k].a]) || isFree(index_[loops_[k].b])) loops.push_back(k);
  for (std::size_t i = 0; i < nodes_.size(); ++i)
    if (isFree(i)) use(i);
  for (const auto& [a, b] : odometry) use(a), use(b);
  for (const auto k : loops) use(index_[loops_[k].a]), use(index_[loops_[k].b]);
  p.x.reserve(p.node.size());  // edges point into x: it must not move once they are added
  for (const auto i : p.node) p.x.push_back(parameters(nodes_[i].pose));

  // Odometry: trusted (no robust loss), sigmas growing with the distance driven.
  for (const auto& [a, b] : odometry) {
    const Mat4d step = nodes_[a].odometry.inverse() * nodes_[b].odometry;
    const auto edge =
        relativePoseError(step, odometrySqrtInformation(step, options.odometry_sigma_m, options.odometry_sigma_per_m,
                                                        options.odometry_sigma_deg, options.odometry_sigma_deg_per_m));
    p.addEdge(slot[a], slot[b], edge, nullptr);
    if (isFree(a) != isFree(b)) p.boundary_edges.push_back({slot[a], slot[b], edge});
  }
  // Loops: a robust loss discounts false ones, the sooner the less probable the loop model found them.
  for (const auto k : loops)
    p.addLoopEdge(k, slot[index_[loops_[k].a]], slot[index_[loops_[k].b]], loopEdge(loops_[k], options),
                  options.loss_scale, loopLossFactor(loops_[k].probability, options.trusted_probability));
  for (std::size_t s = 0; s < p.node.size(); ++s) {
    p.problem.AddParameterBlock(
        p.x[s].data(), 7, new ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>());
    if (!isFree(p.node[s])) p.problem.SetParameterBlockConstant(p.x[s].data());
  }
  // The root session's first node anchors its component (the map frame for the map session's).
  for (const auto& [sid, idx] : sessions_) {
    const auto anchor = sessions_[root(sid)].front();
    if (slot[anchor] != kNone) p.problem.SetParameterBlockConstant(p.x[slot[anchor]].data());
  }
}

MapGraph::Solution MapGraph::solve(const GraphOptimiserOptions& options, std::int64_t solved_through, bool allow_local,
                                   const std::atomic<bool>* cancel) {
  layout();
  initialise();
  // Graduated: when a new loop is far off the current poses (a first optimisation from odometry, a long drift
  // corrected at once), a tight Cauchy loss would discount it along with false ones: solve the whole graph with
  // a wide loss first, then the nominal one. Loops that agree with the warm-started graph need only the second
  // solve, and only around them when the caller allows.
  const bool far_off = newLoopFarOff(options, solved_through);
  const auto free =
      allow_local && options.local_window > 0 && !far_off ? localScope(options, solved_through) : std::vector<char>{};
  GraphProblem p;
  buildProblem(p, options, free);
  const auto run = runSolver(p, options, far_off, kWideLoss * options.loss_scale, cancel);

  Solution out;
  out.converged = run.converged;
  out.iterations = run.iterations;
  out.global = free.empty();
  for (std::size_t s = 0; s < p.node.size(); ++s) {
    const auto i = p.node[s];
    if (!free.empty() && !free[i]) continue;
    nodes_[i].pose.q = Eigen::Quaterniond(p.x[s][3], p.x[s][0], p.x[s][1], p.x[s][2]).normalized();
    nodes_[i].pose.t = Eigen::Vector3d(p.x[s][4], p.x[s][5], p.x[s][6]);
    ++out.free_nodes;
  }
  last_free_ = free;
  const double limit = kRejectChi2 * options.loss_scale * options.loss_scale;
  bool new_rejected = false;
  for (std::size_t k = 0; k < p.loop.size(); ++k) {
    auto& l = loops_[p.loop[k]];
    // Discounted: beyond the 99.9 % point in its own loss scales.
    l.rejected = p.error2(p.loop_edges[k]) > limit * p.loop_loss_factors[k] * p.loop_loss_factors[k];
    new_rejected = new_rejected || (l.rejected && l.id > solved_through);
  }
  out.rejected_loops = rejectedLoops();
  // Strained: the window could not absorb what is new (an edge at its boundary, or a new loop in it, is off by
  // more than the 99.9 % point): the correction reaches beyond it, and a global solve should follow soon. A loop
  // discounted before does not count: it would bring every solve near it forward.
  out.strained = !out.global && (new_rejected || p.maxBoundaryError2() > limit);
  solved_nodes_ = nodes_.size();
  converged_ = out.converged;
  return out;
}

int MapGraph::rejectedLoops() const {
  return static_cast<int>(std::count_if(loops_.begin(), loops_.end(), [](const Loop& l) { return l.rejected; }));
}

bool MapGraph::adopt(const MapGraph& solved) {
  if (solved.nodes_.size() > nodes_.size()) return false;
  for (std::size_t i = 0; i < solved.nodes_.size(); ++i)
    if (solved.nodes_[i].scan_id != nodes_[i].scan_id) return false;
  for (std::size_t i = 0; i < solved.nodes_.size(); ++i) {
    nodes_[i].pose = solved.nodes_[i].pose;
    nodes_[i].initialised = true;
  }
  std::unordered_map<std::int64_t, bool> rejected;
  for (const auto& l : solved.loops_) rejected[l.id] = l.rejected;
  for (auto& l : loops_)
    if (const auto it = rejected.find(l.id); it != rejected.end()) l.rejected = it->second;
  solved_nodes_ = solved.nodes_.size();
  converged_ = solved.converged_;
  last_free_.clear();
  return true;
}

bool MapGraph::hasNew(std::int64_t solved_through) const {
  return nodes_.size() > solved_nodes_ ||
         std::any_of(loops_.begin(), loops_.end(), [&](const Loop& l) { return l.id > solved_through; });
}

MapGraph::Solution MapGraph::settledSolution() const {
  Solution s;
  s.converged = converged_;
  s.global = true;
  s.free_nodes = nodes_.size();
  s.rejected_loops = rejectedLoops();
  return s;
}

std::vector<storage::OptimisedPose> MapGraph::poses() const {
  std::vector<storage::OptimisedPose> out;
  for (const auto& n : nodes_) out.push_back({n.scan_id, n.pose.matrix()});
  return out;
}

std::vector<storage::OptimisedPose> MapGraph::movedPoses() const {
  std::vector<storage::OptimisedPose> out;
  for (std::size_t i = 0; i < nodes_.size(); ++i)
    if (last_free_.empty() || last_free_[i]) out.push_back({nodes_[i].scan_id, nodes_[i].pose.matrix()});
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
