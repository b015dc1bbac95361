// One map's pose graph in memory: scans with odometry poses as nodes, verified loops as edges, and the solve
// that places every session's frame in the map frame. Grows row by row as the database does; not thread-safe
// (the optimiser runs one solve at a time).
#pragma once

#include <Eigen/Geometry>
#include <atomic>
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

struct GraphProblem;

// Why a stored loop cannot be an edge (joins a scan to itself, damaged values), or nullopt.
std::optional<std::string> loopError(const storage::LoopRecord& l);

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
    std::optional<double> probability;  // the loop model's; unknown for loops recorded before it
    bool rejected = false;              // discounted by the robust loss in the last solve that included it
  };
  struct Solution {
    bool converged = false;  // ended by convergence, not by its iteration or time bound
    bool global = true;      // every node was free; false: a local solve around the new loops and scans
    std::size_t iterations = 0;
    std::size_t free_nodes = 0;
    int rejected_loops = 0;  // loops of the whole graph the robust loss discounts (each as of its last solve)
    bool strained = false;   // a local solve whose window could not absorb what is new (see solve)
  };

  // Adds the rows stored since the last call (loops read before nodes, see GraphOptimiser::solve). New nodes
  // start from `kept` (the poses stored by an earlier run) where given, else from odometry. Scans whose pose is
  // not a rigid motion, loops between scans that are not nodes or with damaged values are left out (and
  // logged for `map`). Returns whether the graph changed.
  bool absorb(const std::string& map, const std::vector<storage::LoopRecord>& loops,
              const std::vector<storage::GraphNodeRecord>& nodes, const std::unordered_map<std::int64_t, Mat4d>& kept);

  // Initial guesses for new nodes, then the least-squares solve (odometry edges within sessions, robust loop
  // edges, one fixed node per connected component). Loops with ids up to `solved_through` are already
  // reflected in the poses it starts from.
  //
  // With `allow_local`, only the nodes near what is new are free: scans added since the last solve, and
  // options.local_window nodes on either side (in their session) of each end of every new loop; the edges
  // that touch them and the nodes those edges reach (held fixed) make the problem. Its cost then follows the
  // new loops, not the map's size. The solve is global all the same when a new loop is far off the current
  // poses (a drift corrected at once moves far more than a window), or when the window holds half the graph.
  //
  // Throws std::runtime_error when anything is or becomes non-finite or the solver fails; the graph's poses
  // are then not to be trusted (the caller rebuilds it).
  // A set `cancel` stops the solver at its next iteration (it then throws).
  Solution solve(const GraphOptimiserOptions& options, std::int64_t solved_through, bool allow_local,
                 const std::atomic<bool>* cancel = nullptr);
  // Takes the poses of `solved`, a copy of this graph solved globally since (this graph may have grown
  // meanwhile: what is newer stays to be solved); false, changing nothing, when it is not a copy of this graph.
  bool adopt(const MapGraph& solved);
  // Scans added or loops newer than `solved_through` that no solve has included yet.
  bool hasNew(std::int64_t solved_through) const;
  // The solution as it stands (an adopted global solve with nothing newer).
  Solution settledSolution() const;

  // The solved poses: of every node, or of those the last solve left free; and each session's frame in the map
  // frame (identity when it is not connected to it).
  std::vector<storage::OptimisedPose> poses() const;
  std::vector<storage::OptimisedPose> movedPoses() const;
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
  int rejectedLoops() const;
  // The nodes a local solve frees (see solve), or an empty vector when the solve must be global.
  std::vector<char> localScope(const GraphOptimiserOptions& options, std::int64_t solved_through) const;
  // Whether a loop newer than `solved_through` is far off the current poses (needs the graduated global solve).
  bool newLoopFarOff(const GraphOptimiserOptions& options, std::int64_t solved_through) const;
  // The problem over the free nodes (empty `free`: every node) and the nodes their edges reach.
  void buildProblem(GraphProblem& p, const GraphOptimiserOptions& options, const std::vector<char>& free);

  std::vector<Node> nodes_;
  std::unordered_map<std::int64_t, std::size_t> index_;  // scan id -> node
  std::vector<Loop> loops_;
  std::set<std::pair<std::int64_t, std::int64_t>> pairs_;  // (a, b) of the loops above
  std::int64_t last_scan_ = 0, last_loop_ = 0;
  std::int64_t map_session_ = -1;  // the session whose odometry frame is the map frame
  bool converged_ = false;
  int continuations_ = 0;
  std::size_t solved_nodes_ = 0;  // nodes_ [0, solved_nodes_) have been in a solve
  std::vector<char> last_free_;   // the last solve's free nodes when it was local, else empty (all)
  std::map<std::int64_t, std::vector<std::size_t>> sessions_;  // session -> its nodes in sequence order
  std::vector<std::size_t> position_;                          // node -> its place in its session's list
  std::map<std::int64_t, std::int64_t> parent_;                // union-find over sessions linked by loops
};

}  // namespace sglc::posegraph
