// sglc-bench-graph: time of the server's pose-graph optimisation per loop event on a map of several thousand
// scans, printed as one JSON object.
//
// The map: robot r0 drives KITTI 00's path (4541 frames when ../shared/data is present, else laps of the
// built-in route) with drifting odometry (1 %); robots r1, r2, ... (up to --robots) drive it again from its
// start, each in an unrelated odometry frame with its own drift, up to --scans scans in all (100k scans: 23
// robots). Loops: every pair of r0's frames less than 3 m and more than 100 frames apart (at most 3 per query
// frame, the nearest), and each later robot's frame with the r0 frame it repeats, with the relative pose
// disturbed by 1 cm / 0.02 deg and an information matrix to match. All but the last --events query frames'
// loops are in the map first; one cold optimisation runs; then each remaining query frame's loops arrive as one
// event and the map is optimised again, warm-started, as the server's worker does (local or global, as it
// would decide, global solves in the background included). A last global solve then settles the map.
//
//   build/bin/sglc-bench-graph [--scans 5000] [--robots 2] [--events 50] [--local-window 100]
//                              [--dir /tmp/sglc-bench-graph]
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>

#include "bench/graph_fixture.hpp"
#include "bench/kitti_path.hpp"
#include "sglc/descriptors.hpp"
#include "sglc/elapsed.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"
#include "sglc/version.hpp"
#include "sim/ground_truth.hpp"
#include "sim/simulator.hpp"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using namespace sglc;

// Loops' relative poses are disturbed by this much, and their information matrix says so.
constexpr double kSigmaM = 0.01, kSigmaRad = 0.02 * 3.14159265358979 / 180.0;

struct Options {
  std::string dir = (fs::temp_directory_path() / "sglc-bench-graph").string();
  std::string data = "../shared/data";
  int scans = 5000, events = 50, robots = 2;
  int local_window = posegraph::GraphOptimiserOptions{}.local_window;
};

void addOptions(CLI::App& app, Options& o) {
  app.add_option("--dir", o.dir, "scratch directory (removed first)")->capture_default_str();
  app.add_option("--data", o.data, "shared data directory (KITTI poses)")->capture_default_str();
  app.add_option("--scans", o.scans, "scans in the map")->capture_default_str()->check(CLI::Range(200, 200000));
  app.add_option("--events", o.events, "loop events timed on the full map")
      ->capture_default_str()
      ->check(CLI::Range(1, 10000));
  app.add_option("--robots", o.robots, "robots driving the path (all but r0 repeat it)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  app.add_option("--local-window", o.local_window, "pose_graph.local_window (0: every solve global)")
      ->capture_default_str()
      ->check(CLI::Range(0, 100000));
}

// Ground truth and drifting odometry of each robot: r0 drives the path, the others repeat its start in
// unrelated odometry frames.
struct Robot {
  std::vector<Mat4d> gt, odom;
  std::vector<int> src;
  int size() const { return static_cast<int>(gt.size()); }
};

std::vector<Robot> makeRobots(const sim::Trajectory& traj, int scans, int robots) {
  std::vector<Robot> out;
  const int path = static_cast<int>(traj.poses.size());
  for (int k = 0, left = scans; k < robots && left > 0; ++k) {
    const int n = std::min(left, path);
    left -= n;
    Robot r;
    r.gt.assign(traj.poses.begin(), traj.poses.begin() + n);
    r.src.resize(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) r.src[static_cast<std::size_t>(i)] = i;
    r.odom = sim::driftingOdometry(r.gt, r.src, sim::OdometryNoise{0.01, 0.005}, 11 + static_cast<unsigned>(k));
    if (k > 0) {
      Mat4d unrelated = Mat4d::Identity();
      unrelated.block<3, 3>(0, 0) = Eigen::AngleAxisd(1.0 * k, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      unrelated.block<3, 1>(0, 3) = Eigen::Vector3d(50.0 * k, -20, 3);
      for (auto& T : r.odom) T = unrelated * T;
    }
    out.push_back(std::move(r));
  }
  return out;
}

storage::LoopRecord loopRecord(std::int64_t query, std::int64_t candidate, const Mat4d& T) {
  return bench::loopRecord(query, candidate, T, kSigmaM, kSigmaRad);
}

using LoopGroups = std::vector<std::vector<storage::LoopRecord>>;

// Loops grouped by the query frame that finds them, in the order they would arrive: r0's own loops (at most
// 3 per query frame, the nearest), then each later robot's frame with the r0 frame it repeats.
LoopGroups loopGroups(const std::vector<Robot>& robots, const std::vector<std::vector<std::int64_t>>& ids,
                      sim::Rng& rng) {
  LoopGroups groups;
  const auto& id0 = ids[0];
  std::map<int, std::vector<sim::LoopPose>> by_query;
  for (const auto& l : sim::loopPoses(robots[0].gt, robots[0].src, 3.0, 100)) by_query[l.second].push_back(l);
  for (auto& [q, ls] : by_query) {
    std::sort(ls.begin(), ls.end(), [](const sim::LoopPose& a, const sim::LoopPose& b) {
      return a.T.topRightCorner<3, 1>().norm() < b.T.topRightCorner<3, 1>().norm();
    });
    std::vector<storage::LoopRecord> g;
    for (std::size_t k = 0; k < std::min<std::size_t>(3, ls.size()); ++k)
      // loopPoses' T maps `first` (earlier, the candidate) into `second` (the query).
      g.push_back(loopRecord(id0[static_cast<std::size_t>(q)], id0[static_cast<std::size_t>(ls[k].first)],
                             bench::disturbed(ls[k].T, rng, kSigmaM, kSigmaRad)));
    groups.push_back(std::move(g));
  }
  for (std::size_t k = 1; k < robots.size(); ++k)
    for (std::size_t i = 0; i < ids[k].size(); ++i)  // frame i of robot k is where r0's frame i was
      groups.push_back({loopRecord(ids[k][i], id0[i], bench::disturbed(Mat4d::Identity(), rng, kSigmaM, kSigmaRad))});
  return groups;
}

// r0's trajectory as stored (optimised) against the truth.
double ateOptimised(const storage::MapStore& store, const Robot& r0, const std::vector<std::int64_t>& id0) {
  std::map<std::int64_t, Mat4d> opt;
  for (const auto& p : store.optimisedPoses("m", "", "", 0, std::numeric_limits<std::int64_t>::max()))
    opt[p.scan_id] = p.pose;
  std::vector<Mat4d> est;
  for (const auto id : id0) est.push_back(opt.at(id));
  return bench::ate(est, r0.gt);
}

struct Timings {
  std::size_t loops = 0;  // recorded in the map
  double cold_ms = 0, settle_ms = 0;
  std::vector<double> event_ms;
  int global_events = 0;
  std::vector<double> free_nodes;
  double ate_events = 0, ate_settled = 0;  // r0's, after the timed events, and after the last global solve
};

// All but the last `events` groups go in first and are optimised cold; then each remaining group arrives as
// one event and the map is optimised again, warm-started; then one global solve settles it.
Timings optimise(storage::MapStore& store, const LoopGroups& groups, const Options& options, const Robot& r0,
                 const std::vector<std::int64_t>& id0) {
  const int timed = std::min<int>(options.events, static_cast<int>(groups.size()) - 1);
  Timings t;
  for (std::size_t k = 0; k + static_cast<std::size_t>(timed) < groups.size(); ++k)
    for (const auto& r : groups[k]) t.loops += store.addLoop("m", r) > 0;
  posegraph::GraphOptimiserOptions o;
  o.max_seconds = 600;
  o.max_continuations = 0;  // each timed optimiseNow is the only solve of its loops
  o.local_window = options.local_window;
  // Global solves as the server runs them: in the background within global_interval_s of a local solve, at once
  // after a strained one; an event that adopts one counts as global.
  // Its worker's start-up solve of the map may run first; optimiseNow then returns that solve's event.
  posegraph::GraphOptimiser graph(store, o);
  t.cold_ms = graph.optimiseNow("m").optimise_ms;
  for (std::size_t k = groups.size() - static_cast<std::size_t>(timed); k < groups.size(); ++k) {
    for (const auto& r : groups[k]) t.loops += store.addLoop("m", r) > 0;
    const auto event = graph.optimiseNow("m");
    t.event_ms.push_back(event.optimise_ms);
    t.global_events += event.global;
    t.free_nodes.push_back(static_cast<double>(event.free_nodes));
  }
  t.ate_events = ateOptimised(store, r0, id0);
  t.settle_ms = graph.optimiseNow("m", posegraph::GraphOptimiser::Scope::kGlobal).optimise_ms;
  t.ate_settled = ateOptimised(store, r0, id0);
  graph.stop();
  return t;
}

// Fills the map, times the optimisations and returns the report.
nlohmann::ordered_json run(const sim::Trajectory& traj, const std::vector<Robot>& robots, storage::MapStore& store,
                           const Options& options) {
  sim::Rng rng(7);
  const auto t_fill = Clock::now();
  std::vector<std::vector<std::int64_t>> ids;
  int scans = 0;
  for (std::size_t k = 0; k < robots.size(); ++k) {
    ids.push_back(bench::addScans(store, "r" + std::to_string(k), robots[k].odom, robots[k].size(), rng));
    scans += robots[k].size();
  }
  const double fill_s = std::chrono::duration<double>(Clock::now() - t_fill).count();
  const auto t = optimise(store, loopGroups(robots, ids, rng), options, robots[0], ids[0]);
  nlohmann::ordered_json out;
  out["trajectory"] = traj.source;
  out["scans"] = scans;
  out["robots"] = robots.size();
  out["loops"] = t.loops;
  out["local_window"] = options.local_window;
  out["fill_s"] = fill_s;
  out["cold_optimisation_ms"] = t.cold_ms;
  out["loop_event_ms"] = {{"median", percentile(t.event_ms, 0.5)},
                          {"p90", percentile(t.event_ms, 0.9)},
                          {"max", percentile(t.event_ms, 1.0)},
                          {"n", t.event_ms.size()},
                          {"global", t.global_events},
                          {"free_nodes_median", percentile(t.free_nodes, 0.5)}};
  out["global_settle_ms"] = t.settle_ms;
  out["ate_odometry_r0_m"] = bench::ate(robots[0].odom, robots[0].gt);
  out["ate_after_events_r0_m"] = t.ate_events;
  out["ate_optimised_r0_m"] = t.ate_settled;
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Pose-graph optimisation benchmark (JSON on stdout)."};
  app.set_version_flag("--version", std::string("sglc-bench-graph ") + sglc::kVersion);
  Options options;
  addOptions(app, options);
  CLI11_PARSE(app, argc, argv);
  // The optimiser logs each event; stdout carries only the JSON.
  spdlog::set_default_logger(spdlog::stderr_logger_st("bench"));

  fs::remove_all(options.dir);
  fs::create_directories(options.dir);
  const sim::Trajectory traj = bench::kitti00OrLoopRoute(options.data);
  const auto robots = makeRobots(traj, options.scans, options.robots);
  {
    const auto store =
        bench::openGraphStore(options.dir);  // closed before its directory goes (it writes an index snapshot)
    std::cout << run(traj, robots, *store, options).dump(2) << std::endl;
  }
  fs::remove_all(options.dir);
  return 0;
}
