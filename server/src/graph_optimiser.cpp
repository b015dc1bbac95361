#include "graph_optimiser.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <vector>

#include "log_line.hpp"
#include "sglc/rigid.hpp"

namespace sglc::server {

using Clock = std::chrono::steady_clock;

namespace {

constexpr double kRadPerDeg = 3.14159265358979323846 / 180.0;
constexpr double kWideLoss = 10.0;  // loss scale of the first solve, in nominal loss scales

struct Pose {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  static Pose of(const Mat4d& T) {
    Pose p;
    p.q = Eigen::Quaterniond(T.block<3, 3>(0, 0)).normalized();
    p.t = T.block<3, 1>(0, 3);
    return p;
  }
  Mat4d matrix() const {
    Mat4d T = Mat4d::Identity();
    T.block<3, 3>(0, 0) = q.normalized().toRotationMatrix();
    T.block<3, 1>(0, 3) = t;
    return T;
  }
};

// Residual of a relative-pose measurement T_ab (maps b's points into a's frame) between poses a and b (both
// scan -> map): translation and rotation of inv(T_ab) * inv(T_a) * T_b, i.e. the right perturbation
// (translation first) that takes T_ab to the predicted relative pose, whitened by an upper-triangular square
// root of the edge's information (information = sqrt_info' * sqrt_info).
using Mat6 = Eigen::Matrix<double, 6, 6>;
struct RelativePoseError {
  Eigen::Quaterniond q_ab;
  Eigen::Vector3d t_ab;
  Mat6 sqrt_info;
  // A pose is 7 numbers: quaternion x, y, z, w, then translation.
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    Eigen::Map<const Eigen::Quaternion<T>> qa(a), qb(b);
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> ta(a + 4), tb(b + 4);
    const Eigen::Quaternion<T> qa_inv = qa.conjugate();
    const Eigen::Quaternion<T> q_pred = qa_inv * qb;
    const Eigen::Matrix<T, 3, 1> t_pred = qa_inv * (tb - ta);
    const Eigen::Quaternion<T> dq = q_ab.template cast<T>().conjugate() * q_pred;
    Eigen::Matrix<T, 6, 1> e;
    e.template head<3>() = q_ab.template cast<T>().conjugate() * (t_pred - t_ab.template cast<T>());
    e.template tail<3>() = T(2.0) * dq.vec();
    Eigen::Map<Eigen::Matrix<T, 6, 1>> out(r);
    out = sqrt_info.template cast<T>() * e;
    return true;
  }
};

Mat6 diagonalSqrtInformation(double sigma_t, double sigma_r) {
  Mat6 S = Mat6::Zero();
  S.diagonal() << 1 / sigma_t, 1 / sigma_t, 1 / sigma_t, 1 / sigma_r, 1 / sigma_r, 1 / sigma_r;
  return S;
}

// A loop's registration information, with a floor covariance added (no registration is better than its model:
// planes are not perfectly flat, labels not perfectly right), as an upper-triangular square root.
Mat6 loopSqrtInformation(const Mat6& information, double floor_t, double floor_r) {
  const Eigen::SelfAdjointEigenSolver<Mat6> eig(0.5 * (information + information.transpose()));
  Eigen::Matrix<double, 6, 1> var;
  for (int k = 0; k < 6; ++k) var[k] = 1.0 / std::max(eig.eigenvalues()[k], 1e-12);  // free directions: huge
  Mat6 cov = eig.eigenvectors() * var.asDiagonal() * eig.eigenvectors().transpose();
  cov.diagonal().head<3>().array() += floor_t * floor_t;
  cov.diagonal().tail<3>().array() += floor_r * floor_r;
  const Mat6 info = cov.inverse();
  return Eigen::LLT<Mat6>(0.5 * (info + info.transpose())).matrixU();
}

// Why a stored loop cannot be an edge, or nullopt.
std::optional<std::string> loopError(const storage::LoopRecord& l) {
  if (l.query_scan == l.candidate_scan) return std::string("joins a scan to itself");
  if (const auto error = rigidMotionError(l.T)) return "transform " + *error;
  if (l.information && !l.information->allFinite()) return std::string("information is not finite");
  if (!std::isfinite(l.rmse)) return std::string("rmse is not finite");
  return std::nullopt;
}

}  // namespace

struct GraphOptimiser::MapGraph {
  struct Node {
    std::int64_t scan_id;
    std::int64_t session_id;
    std::int64_t seq;
    Mat4d odometry;
    Pose pose;
    bool initialised = false;
  };
  struct Loop {
    std::int64_t id, a, b;  // a = query scan, b = candidate scan; T maps b into a
    Mat4d T;
    double rmse, fitness;
    std::optional<Mat6d> information;
  };
  std::vector<Node> nodes;
  std::unordered_map<std::int64_t, std::size_t> index;  // scan id -> node
  std::vector<Loop> loops;
  std::set<std::pair<std::int64_t, std::int64_t>> pairs;  // (a, b) of the loops above
  std::int64_t last_scan = 0, last_loop = 0;
  std::int64_t map_session = -1;  // the session whose odometry frame is the map frame
  bool converged = false;         // the last solve ended by convergence (not by its iteration or time bound)
  int continuations = 0;          // solves since the last new scans or loops (each one continued the previous)
};

GraphOptimiser::GraphOptimiser(storage::MapStore& store, GraphOptimiserOptions options)
    : store_(store), options_(options) {
  const auto now = Clock::now();
  for (const auto& m : store_.listMaps())
    if (!store_.loops(m.name).empty()) due_[m.name] = now;
  worker_ = std::thread([this] { run(); });
}

GraphOptimiser::~GraphOptimiser() {
  stop();
  if (worker_.joinable()) worker_.join();
}

void GraphOptimiser::stop() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  changed_.notify_all();
}

bool GraphOptimiser::stopping() const {
  std::lock_guard lock(mutex_);
  return stop_;
}

void GraphOptimiser::loopsAdded(const std::string& map) {
  {
    std::lock_guard lock(mutex_);
    if (!due_.count(map)) due_[map] = Clock::now() + options_.debounce;
  }
  wake_.notify_all();
}

void GraphOptimiser::scansRemoved(const std::string& map) {
  {
    std::lock_guard lock(mutex_);
    stale_.insert(map);
    due_[map] = Clock::now();
  }
  wake_.notify_all();
}

std::optional<GraphEvent> GraphOptimiser::waitForVersion(const std::string& map, std::int64_t after,
                                                         std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  const bool ready = changed_.wait_for(lock, timeout, [&] {
    if (stop_) return true;
    const auto it = latest_.find(map);
    return it != latest_.end() && it->second.graph_version > after;
  });
  const auto it = latest_.find(map);
  if (!ready || stop_ || it == latest_.end() || it->second.graph_version <= after) return std::nullopt;
  return it->second;
}

void GraphOptimiser::run() {
  std::unique_lock lock(mutex_);
  while (!stop_) {
    if (due_.empty()) {
      wake_.wait(lock);
      continue;
    }
    auto next =
        std::min_element(due_.begin(), due_.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
    if (next->second > Clock::now()) {
      wake_.wait_until(lock, next->second);
      continue;
    }
    const std::string map = next->first;
    due_.erase(next);
    lock.unlock();
    optimise(map);  // never throws: a failure becomes the map's failed event
    lock.lock();
  }
}

GraphEvent GraphOptimiser::optimiseNow(const std::string& map) { return optimise(map); }

GraphEvent GraphOptimiser::optimise(const std::string& map) {
  std::lock_guard one(optimise_mutex_);
  try {
    return solve(map);
  } catch (const std::exception& e) {
    // The map keeps its last good poses; its graph is rebuilt from the database on the next attempt.
    graphs_.erase(map);
    GraphEvent event = latest(map).value_or(GraphEvent{});
    try {
      if (!event.graph_version) event.graph_version = store_.graphVersion(map);
    } catch (const std::exception&) {
      // the database failed too: the event says 0
    }
    event.failed = true;
    event.converged = false;
    event.error = e.what();
    spdlog::error(
        "{}",
        logLine(
            {{"event", "optimise_failed"}, {"map", map}, {"version", event.graph_version}, {"error", event.error}}));
    publish(map, event);
    return event;
  }
}

GraphEvent GraphOptimiser::solve(const std::string& map) {
  const auto t0 = Clock::now();
  auto& slot = graphs_[map];
  {
    std::lock_guard lock(mutex_);
    if (stale_.erase(map)) slot.reset();
  }
  if (!slot) slot = std::make_unique<MapGraph>();
  MapGraph& g = *slot;

  // New rows since the last optimisation (after a deletion, all rows: the graph was dropped above). Loops are
  // read before scans: ingest stores a scan before its loops, so every loop read here finds its scans among the
  // nodes read after it (read the other way round, a scan and its loop stored between the two reads would give
  // a loop without its node, skipped and never read again).
  auto loops = store_.loops(map, g.last_loop);
  auto nodes = store_.graphNodes(map, g.last_scan);
  // Loops with ids up to solved_through are reflected in the poses the solve starts from: the last solve's,
  // or, for a fresh graph (server start, after a deletion), the poses kept in the database, so that a restart
  // continues from where the last run stopped.
  std::int64_t solved_through = g.last_loop;
  const bool fresh = g.nodes.empty();
  bool changed = false;
  std::unordered_map<std::int64_t, Mat4d> kept;
  if (fresh) {
    for (const auto& p : store_.optimisedPoses(map, "", "", 0, std::numeric_limits<std::int64_t>::max()))
      if (!rigidMotionError(p.pose)) kept[p.scan_id] = orthonormalised(p.pose);  // else start from odometry
    solved_through = store_.optimisedThroughLoop(map);
  }
  for (const auto& n : nodes) {
    g.last_scan = std::max(g.last_scan, n.scan_id);
    if (!n.odometry_pose) continue;
    // Files written before the server checked poses may hold ones that are not rigid motions: such a scan is
    // no graph node (a pose graph cannot use it), but it stays in the map.
    if (const auto error = rigidMotionError(*n.odometry_pose)) {
      spdlog::warn("{}", logLine({{"event", "graph_node_skipped"},
                                  {"map", map},
                                  {"scan", n.scan_id},
                                  {"error", "odometry pose " + *error}}));
      continue;
    }
    changed = true;
    g.index[n.scan_id] = g.nodes.size();
    const auto k = kept.find(n.scan_id);
    const Mat4d odometry = orthonormalised(*n.odometry_pose);
    g.nodes.push_back(
        {n.scan_id, n.session_id, n.seq, odometry, Pose::of(k != kept.end() ? k->second : odometry), k != kept.end()});
    g.map_session = g.map_session < 0 ? n.session_id : std::min(g.map_session, n.session_id);
  }
  for (const auto& l : loops) {
    g.last_loop = std::max(g.last_loop, l.id);
    if (!g.index.count(l.query_scan) || !g.index.count(l.candidate_scan)) continue;
    if (const auto error = loopError(l)) {
      spdlog::warn("{}", logLine({{"event", "graph_loop_skipped"}, {"map", map}, {"loop", l.id}, {"error", *error}}));
      continue;
    }
    // A second loop for the same pair replaced the first in the database: drop the first here too.
    if (!g.pairs.insert({l.query_scan, l.candidate_scan}).second)
      g.loops.erase(std::find_if(g.loops.begin(), g.loops.end(),
                                 [&](const auto& o) { return o.a == l.query_scan && o.b == l.candidate_scan; }));
    g.loops.push_back({l.id, l.query_scan, l.candidate_scan, orthonormalised(l.T), l.rmse, l.fitness, l.information});
    changed = true;
  }
  // A solved graph with nothing new would only be solved again to the same poses: report the last event, no new
  // version (a request queued while an optimisation was running is often already covered by it).
  if (!fresh && !changed && g.converged) {
    std::lock_guard lock(mutex_);
    const auto it = latest_.find(map);
    if (it != latest_.end()) return it->second;
  }

  // Sessions and their scans in sequence order; initial guesses for new nodes.
  std::map<std::int64_t, std::vector<std::size_t>> sessions;
  for (std::size_t i = 0; i < g.nodes.size(); ++i) sessions[g.nodes[i].session_id].push_back(i);
  for (auto& [sid, idx] : sessions)
    std::stable_sort(idx.begin(), idx.end(),
                     [&](std::size_t a, std::size_t b) { return g.nodes[a].seq < g.nodes[b].seq; });

  // Components: sessions linked by loops (union-find); the map frame's component is "connected".
  std::map<std::int64_t, std::int64_t> parent;
  for (const auto& [sid, idx] : sessions) parent[sid] = sid;
  auto find = [&](std::int64_t s) {
    while (parent[s] != s) s = parent[s] = parent[parent[s]];
    return s;
  };
  for (const auto& l : g.loops) {
    const auto a = find(g.nodes[g.index[l.a]].session_id), b = find(g.nodes[g.index[l.b]].session_id);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);  // the smaller session id is the root
  }

  // Initialise sessions: the map session and each component's root in their own odometry frames; other
  // sessions through their first loop to an initialised session; nodes by chaining odometry.
  auto initSession = [&](std::int64_t sid, const Mat4d& T_frame) {
    for (auto i : sessions[sid]) {
      auto& n = g.nodes[i];
      if (n.initialised) continue;
      // Chain from the previous initialised node of the session, else place by the session frame.
      const auto& idx = sessions[sid];
      const auto pos = std::find(idx.begin(), idx.end(), i) - idx.begin();
      if (pos > 0 && g.nodes[idx[static_cast<std::size_t>(pos - 1)]].initialised) {
        const auto& prev = g.nodes[idx[static_cast<std::size_t>(pos - 1)]];
        n.pose = Pose::of(prev.pose.matrix() * prev.odometry.inverse() * n.odometry);
      } else {
        n.pose = Pose::of(T_frame * n.odometry);
      }
      n.initialised = true;
    }
  };
  std::set<std::int64_t> placed;
  for (const auto& [sid, idx] : sessions) {
    const bool any = std::any_of(idx.begin(), idx.end(), [&](std::size_t i) { return g.nodes[i].initialised; });
    if (any || find(sid) == sid) {
      const auto& first = g.nodes[idx.front()];
      initSession(sid, any ? Mat4d(first.pose.matrix() * first.odometry.inverse()) : Mat4d::Identity());
      placed.insert(sid);
    }
  }
  for (bool progress = true; progress;) {
    progress = false;
    for (const auto& l : g.loops) {
      const auto& na = g.nodes[g.index[l.a]];
      const auto& nb = g.nodes[g.index[l.b]];
      const bool pa = placed.count(na.session_id), pb = placed.count(nb.session_id);
      if (pa == pb) continue;
      // T_map_b = T_map_a * T_ab (or the inverse way round); the unplaced session's frame follows.
      if (pa) {
        const Mat4d T_map_b = na.pose.matrix() * l.T;
        initSession(nb.session_id, T_map_b * nb.odometry.inverse());
        placed.insert(nb.session_id);
      } else {
        const Mat4d T_map_a = nb.pose.matrix() * l.T.inverse();
        initSession(na.session_id, T_map_a * na.odometry.inverse());
        placed.insert(na.session_id);
      }
      progress = true;
    }
  }
  for (const auto& [sid, idx] : sessions) initSession(sid, Mat4d::Identity());

  // The problem: odometry edges within sessions, robust loop edges, one fixed node per component.
  ceres::Problem problem;
  std::vector<std::array<double, 7>> x(g.nodes.size());  // per node: quaternion (x, y, z, w), translation
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    const auto& p = g.nodes[i].pose;
    x[i] = {p.q.x(), p.q.y(), p.q.z(), p.q.w(), p.t.x(), p.t.y(), p.t.z()};
  }
  auto edge = [](const Mat4d& T_ab, const Mat6& sqrt_info) {
    return RelativePoseError{Eigen::Quaterniond(T_ab.block<3, 3>(0, 0)).normalized(), T_ab.block<3, 1>(0, 3),
                             sqrt_info};
  };
  auto addEdge = [&](std::size_t a, std::size_t b, const RelativePoseError& e, ceres::LossFunction* loss) {
    auto* cost = new ceres::AutoDiffCostFunction<RelativePoseError, 6, 7, 7>(new RelativePoseError(e));
    problem.AddResidualBlock(cost, loss, x[a].data(), x[b].data());
  };
  for (const auto& [sid, idx] : sessions)
    for (std::size_t k = 1; k < idx.size(); ++k) {
      const auto& a = g.nodes[idx[k - 1]];
      const auto& b = g.nodes[idx[k]];
      const Mat4d step = a.odometry.inverse() * b.odometry;
      const double d = step.block<3, 1>(0, 3).norm();
      // Odometry: trusted (no robust loss), sigmas growing with the distance driven.
      addEdge(idx[k - 1], idx[k],
              edge(step, diagonalSqrtInformation(
                             options_.odometry_sigma_m + options_.odometry_sigma_per_m * d,
                             (options_.odometry_sigma_deg + options_.odometry_sigma_deg_per_m * d) * kRadPerDeg)),
              nullptr);
    }
  std::vector<RelativePoseError> loop_edges;
  std::vector<ceres::LossFunctionWrapper*> loop_losses;  // owned by the problem
  const double floor_r = options_.loop_sigma_deg * kRadPerDeg;
  for (const auto& l : g.loops) {
    // Loops: the registration's information plus a floor covariance, or (loops recorded without one) a sigma
    // from the refinement's residual; a robust loss discounts false ones.
    if (l.information) {
      loop_edges.push_back(edge(l.T, loopSqrtInformation(*l.information, options_.loop_sigma_m, floor_r)));
    } else {
      const double st = std::max(options_.loop_sigma_m, l.rmse);
      loop_edges.push_back(edge(l.T, diagonalSqrtInformation(st, floor_r * st / options_.loop_sigma_m)));
    }
    loop_losses.push_back(
        new ceres::LossFunctionWrapper(new ceres::CauchyLoss(options_.loss_scale), ceres::TAKE_OWNERSHIP));
    addEdge(g.index[l.a], g.index[l.b], loop_edges.back(), loop_losses.back());
  }
  // Graduated: when a new loop is far off the current poses (a first optimisation from odometry, a long drift
  // corrected at once), a tight Cauchy loss would discount it along with false ones: solve with a wide loss
  // first, then the nominal one. Loops that agree with the warm-started graph need only the second solve.
  // Whitened residual of loop k at the current poses, squared.
  auto loopError2 = [&](std::size_t k) {
    Eigen::Matrix<double, 6, 1> r;
    loop_edges[k](x[g.index[g.loops[k].a]].data(), x[g.index[g.loops[k].b]].data(), r.data());
    return r.squaredNorm();
  };
  bool wide = false;
  for (std::size_t k = 0; k < g.loops.size() && !wide; ++k)
    wide = g.loops[k].id > solved_through && loopError2(k) > std::pow(kWideLoss * options_.loss_scale, 2);
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    problem.AddParameterBlock(
        x[i].data(), 7, new ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>());
  }
  std::set<std::int64_t> fixed_roots;
  for (const auto& [sid, idx] : sessions)
    if (fixed_roots.insert(find(sid)).second) {
      // The root session's first node anchors its component (the map frame for the map session's).
      const auto first = sessions[find(sid)].front();
      problem.SetParameterBlockConstant(x[first].data());
    }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  so.max_num_iterations = options_.max_iterations;
  so.max_solver_time_in_seconds = options_.max_seconds;
  so.num_threads = 1;  // deterministic
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  // Ceres aborts the process on non-finite parameters: nothing non-finite goes in, and what comes out is checked.
  for (const auto& xi : x)
    for (double v : xi)
      if (!std::isfinite(v)) throw std::runtime_error("a node's initial pose is not finite");
  if (!g.nodes.empty()) {
    double cost = 0;
    if (!problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr) || !std::isfinite(cost))
      throw std::runtime_error("the graph's initial cost is not finite");
  }
  g.converged = g.nodes.empty();  // nothing to solve is solved
  if (!g.nodes.empty()) {
    if (wide) {
      for (auto* loss : loop_losses)
        loss->Reset(new ceres::CauchyLoss(kWideLoss * options_.loss_scale), ceres::TAKE_OWNERSHIP);
      ceres::Solve(so, &problem, &summary);
      for (auto* loss : loop_losses) loss->Reset(new ceres::CauchyLoss(options_.loss_scale), ceres::TAKE_OWNERSHIP);
    }
    ceres::Solver::Summary last;
    ceres::Solve(so, &problem, &last);
    if (!last.IsSolutionUsable()) throw std::runtime_error("the solver failed: " + last.message);
    g.converged = last.termination_type == ceres::CONVERGENCE;
    summary.iterations.insert(summary.iterations.end(), last.iterations.begin(), last.iterations.end());
  }
  for (const auto& xi : x)
    for (double v : xi)
      if (!std::isfinite(v)) throw std::runtime_error("the solution is not finite");
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    g.nodes[i].pose.q = Eigen::Quaterniond(x[i][3], x[i][0], x[i][1], x[i][2]).normalized();
    g.nodes[i].pose.t = Eigen::Vector3d(x[i][4], x[i][5], x[i][6]);
  }

  // Loops the robust loss discounted: whitened squared error beyond the 99.9 % point of a chi-square with six
  // degrees of freedom (22.46), in loss scales (the Cauchy weight there is below 0.05).
  int rejected = 0;
  for (std::size_t k = 0; k < g.loops.size(); ++k)
    rejected += loopError2(k) > 22.46 * options_.loss_scale * options_.loss_scale;

  std::vector<storage::OptimisedPose> poses;
  for (const auto& n : g.nodes) poses.push_back({n.scan_id, n.pose.matrix()});
  std::vector<storage::SessionFrame> frames;
  const auto map_root = g.map_session < 0 ? -1 : find(g.map_session);
  for (const auto& [sid, idx] : sessions) {
    const auto& first = g.nodes[idx.front()];
    storage::SessionFrame f;
    f.session_id = sid;
    f.connected = find(sid) == map_root;
    f.T_map_session = f.connected ? Mat4d(first.pose.matrix() * first.odometry.inverse()) : Mat4d::Identity();
    frames.push_back(f);
  }
  GraphEvent event;
  event.graph_version = store_.saveOptimised(map, poses, frames, g.last_loop);
  event.loops = static_cast<std::int64_t>(g.loops.size());
  event.nodes = static_cast<std::int64_t>(g.nodes.size());
  event.rejected_loops = rejected;
  event.optimise_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  event.converged = g.converged;
  // Stopped at a bound: carry on from here soon (the worker; optimiseNow callers see converged = false), but
  // not forever on a graph that never meets Ceres' tolerances.
  g.continuations = changed ? 0 : g.continuations + 1;  // new rows: a new problem
  if (!g.converged && g.continuations < options_.max_continuations) {
    {
      std::lock_guard lock(mutex_);
      if (!due_.count(map)) due_[map] = Clock::now() + options_.debounce;
    }
    wake_.notify_all();
  }
  spdlog::info("{}", logLine({{"event", "optimised"},
                              {"map", map},
                              {"version", event.graph_version},
                              {"nodes", event.nodes},
                              {"loops", event.loops},
                              {"rejected", rejected},
                              {"iterations", summary.iterations.size()},
                              {"converged", event.converged},
                              {"ms", std::round(event.optimise_ms * 10) / 10}}));
  publish(map, event);
  return event;
}

void GraphOptimiser::publish(const std::string& map, const GraphEvent& event) {
  {
    std::lock_guard lock(mutex_);
    latest_[map] = event;
  }
  changed_.notify_all();
  std::lock_guard lock(listeners_mutex_);
  for (const auto& [id, listener] : listeners_) listener(map, event);
}

std::optional<GraphEvent> GraphOptimiser::latest(const std::string& map) const {
  std::lock_guard lock(mutex_);
  const auto it = latest_.find(map);
  if (it == latest_.end()) return std::nullopt;
  return it->second;
}

std::uint64_t GraphOptimiser::subscribe(Listener listener) {
  std::lock_guard lock(listeners_mutex_);
  const auto id = next_listener_++;
  listeners_[id] = std::move(listener);
  return id;
}

void GraphOptimiser::unsubscribe(std::uint64_t id) {
  std::lock_guard lock(listeners_mutex_);
  listeners_.erase(id);
}

}  // namespace sglc::server
