// One map's pose graph in memory: scans with odometry poses as nodes, verified loops as edges, and the solve
// that places every session's frame in the map frame. Grows row by row as the database does; not thread-safe
// (the optimiser runs one solve at a time).
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::posegraph {

// A pose as a unit quaternion and a translation (what the solver optimises).
struct Pose {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  static Pose of(const Mat4d& T);
  Mat4d matrix() const;
};

class MapGraph {
 public:
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
    double rmse;
    std::optional<Mat6d> information;
  };
  struct Solution {
    bool converged = false;  // ended by convergence, not by its iteration or time bound
    std::size_t iterations = 0;
    int rejected_loops = 0;  // loops the robust loss discounted
  };

  // Adds the rows stored since the last call (loops read before nodes, see GraphOptimiser::solve). New nodes
  // start from `kept` (the poses stored by an earlier run) where given, else from odometry. Scans whose pose is
  // not a rigid motion, loops between scans that are not nodes or with damaged values are left out (and
  // logged for `map`). Returns whether the graph changed.
  bool absorb(const std::string& map, const std::vector<storage::LoopRecord>& loops,
              const std::vector<storage::GraphNodeRecord>& nodes, const std::unordered_map<std::int64_t, Mat4d>& kept);

  // Initial guesses for new nodes, then the least-squares solve (odometry edges within sessions, robust loop
  // edges, one fixed node per connected component). Loops with ids up to `solved_through` are already
  // reflected in the poses it starts from. Throws std::runtime_error when anything is or becomes non-finite
  // or the solver fails; the graph's poses are then not to be trusted (the caller rebuilds it).
  Solution solve(const GraphOptimiserOptions& options, std::int64_t solved_through);

  // The solved poses, and each session's frame in the map frame (identity when it is not connected to it).
  std::vector<storage::OptimisedPose> poses() const;
  std::vector<storage::SessionFrame> frames();

  bool empty() const { return nodes_.empty(); }
  std::size_t nodeCount() const { return nodes_.size(); }
  std::size_t loopCount() const { return loops_.size(); }
  std::int64_t lastScan() const { return last_scan_; }
  std::int64_t lastLoop() const { return last_loop_; }
  bool converged() const { return converged_; }
  // Solves since the last new scans or loops (each continued the previous one).
  int continuations() const { return continuations_; }
  void countSolve(bool changed) { continuations_ = changed ? 0 : continuations_ + 1; }

 private:
  void layout();                            // sessions_ and components_ from the nodes and loops
  std::int64_t root(std::int64_t session);  // the component's root session (union-find)
  void initialiseSession(std::int64_t session, const Mat4d& T_map_frame);
  void initialise();

  std::vector<Node> nodes_;
  std::unordered_map<std::int64_t, std::size_t> index_;  // scan id -> node
  std::vector<Loop> loops_;
  std::set<std::pair<std::int64_t, std::int64_t>> pairs_;  // (a, b) of the loops above
  std::int64_t last_scan_ = 0, last_loop_ = 0;
  std::int64_t map_session_ = -1;  // the session whose odometry frame is the map frame
  bool converged_ = false;
  int continuations_ = 0;
  std::map<std::int64_t, std::vector<std::size_t>> sessions_;  // session -> its nodes in sequence order
  std::map<std::int64_t, std::int64_t> parent_;                // union-find over sessions linked by loops
};

}  // namespace sglc::posegraph
