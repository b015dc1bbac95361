// sglc-bench-false-loops: how far false loops move the optimised trajectory, with and without the loop model's
// probability in the pose graph (docs/PERFORMANCE.md, "False loops in the pose graph").
//
// Per KITTI sequence (00, 05, 08: their ground-truth trajectories only, in ../shared/data/kitti_odometry_gt_poses;
// without them, the simulator's built-in route): drifting odometry (1 %, 0.005 deg/m), the true loops (for each
// query frame the nearest earlier frame within 3 m and more than 100 frames back, disturbed by 5 cm / 0.1 deg
// with an information matrix to match), and a share of them replaced by false ones: the same query and measured
// pose, but a candidate frame 50-800 m from the true one (--false-off-min/max). Probabilities as a verifier would give
// them: true loops uniform in [0.9, 1], false ones in [--false-p-min, --false-p-max] (0.5-0.9); and the same with false
// loops as probable as true ones ([0.9, 1]), where only the robust loss can tell. "kernel" runs store no
// probability (the pose graph as before the loop model). The loops arrive in query order: half of them, a cold
// solve, then --events batches each solved as the server would, then one global solve; the ATE is of that.
// Every random draw comes from --seed (below 100) through the simulator's generator: runs repeat bit for bit.
//
//   build/bin/sglc-bench-false-loops [--seqs 00,05,08] [--fractions 0,1,5,10] [--events 5] [--seed 7]
//                                    [--markdown]
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "bench/graph_fixture.hpp"
#include "sglc/io.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"
#include "sim/ground_truth.hpp"
#include "sim/rng.hpp"
#include "sim/simulator.hpp"

namespace {

namespace fs = std::filesystem;
using namespace sglc;

struct Options {
  std::string dir = (fs::temp_directory_path() / "sglc-bench-false-loops").string();
  std::string data = "../shared/data";
  std::vector<std::string> seqs{"00", "05", "08"};
  std::vector<double> fractions{0, 1, 5, 10};
  int events = 5;
  std::uint64_t seed = 7;
  double false_p_min = 0.5, false_p_max = 0.9;
  double off_min_m = 50, off_max_m = 800;  // how far a false loop's candidate is from the true one
  double trusted = posegraph::GraphOptimiserOptions{}.trusted_probability;
  bool markdown = false;
};

// KITTI camera poses in a z-up LiDAR-like frame (x forward, y left) without a calibration file: the axes only.
Mat4d cameraAxes() {
  Mat4d Tr = Mat4d::Zero();
  Tr(0, 1) = -1;  // camera x (right) = -y (left)
  Tr(1, 2) = -1;  // camera y (down) = -z (up)
  Tr(2, 0) = 1;   // camera z (forward) = x
  Tr(3, 3) = 1;
  return Tr;
}

sim::Trajectory trajectory(const Options& o, const std::string& seq) {
  if (seq != "00" && seq != "05" && seq != "08") throw InputError("--seqs: only 00, 05 and 08 (got " + seq + ")");
  const auto path = o.data + "/kitti_odometry_gt_poses/poses/" + seq + ".txt";
  if (!fs::exists(path)) return sim::loopRoute();
  return sim::kittiTrajectory(readPoses(path), cameraAxes(), path);
}

struct Loop {
  int query, candidate;
  Mat4d T;
  bool truth;
  double p;
};

// Loops measured on the drive: per query frame the nearest earlier frame within 3 m (more than 100 back).
std::vector<Loop> trueLoops(const std::vector<Mat4d>& gt, const std::vector<int>& src, sim::Rng& rng) {
  std::vector<Loop> out;
  for (const auto& l : sim::loopPoses(gt, src, 3.0, 100)) {
    if (!out.empty() && out.back().query == l.second) {
      if (l.T.topRightCorner<3, 1>().norm() >= out.back().T.topRightCorner<3, 1>().norm()) continue;
      out.pop_back();
    }
    out.push_back({l.second, l.first, l.T, true, 1.0});
  }
  for (auto& l : out) l.T = bench::disturbed(l.T, rng, bench::kLoopSigmaM, bench::kLoopSigmaRad);
  return out;
}

// `percent` % of the loops (at random) get a candidate --false-off-min to --false-off-max m (50-800) from the
// true one, keeping query and pose.
void falsify(std::vector<Loop>& loops, const std::vector<Mat4d>& gt, double percent, const Options& o, sim::Rng& rng) {
  const auto n = static_cast<int>(std::lround(percent / 100.0 * static_cast<double>(loops.size())));
  std::vector<int> order(loops.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  for (int i = static_cast<int>(order.size()) - 1; i > 0; --i) std::swap(order[i], order[rng.below(i + 1)]);
  for (int k = 0; k < n; ++k) {
    auto& l = loops[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])];
    const Eigen::Vector3d at = gt[static_cast<std::size_t>(l.candidate)].topRightCorner<3, 1>();
    for (int tries = 0; tries < 100000; ++tries) {
      const int j = rng.below(static_cast<int>(gt.size()));
      const double d = (gt[static_cast<std::size_t>(j)].topRightCorner<3, 1>() - at).norm();
      if (d >= o.off_min_m && d <= o.off_max_m && j != l.query) {
        l.candidate = j;
        l.truth = false;
        break;
      }
    }
  }
}

enum class Mode { kKernel, kProbability, kEquallyProbable };
const char* modeName(Mode m) {
  return m == Mode::kKernel ? "kernel" : m == Mode::kProbability ? "probability" : "equal_probability";
}

// Draws each loop's probability for the mode (the same draws for every mode: one stream per loop).
void assignProbabilities(std::vector<Loop>& loops, Mode mode, const Options& o) {
  for (std::size_t i = 0; i < loops.size(); ++i) {
    sim::Rng rng(sim::hashKeys(o.seed, 0x9B0ULL, i));
    const double u = rng.unit();
    const bool low = !loops[i].truth && mode == Mode::kProbability;
    loops[i].p = low ? o.false_p_min + (o.false_p_max - o.false_p_min) * u : 0.9 + 0.1 * u;
  }
}

// Stores the drive, feeds the loops as the server would see them, returns the settled ATE.
double run(const std::vector<Mat4d>& gt, const std::vector<Mat4d>& odom, const std::vector<Loop>& loops, Mode mode,
           const Options& o) {
  fs::remove_all(o.dir);
  fs::create_directories(o.dir);
  double ate = 0;
  {
    auto store = bench::openGraphStore(o.dir);
    sim::Rng rng(o.seed);
    const auto ids = bench::addScans(*store, "r0", odom, static_cast<int>(odom.size()), rng);
    posegraph::GraphOptimiserOptions go;
    go.max_seconds = 600;
    go.max_continuations = 0;
    go.local_window = 0;  // every solve global: no background solve, so the result does not depend on timing
    go.trusted_probability = mode == Mode::kKernel ? 0.0 : o.trusted;
    posegraph::GraphOptimiser graph(*store, go);
    const std::size_t first = loops.size() / 2;
    const std::size_t batch = std::max<std::size_t>(1, (loops.size() - first + o.events - 1) / o.events);
    for (std::size_t k = 0; k < loops.size(); ++k) {
      const auto& l = loops[k];
      auto r = bench::loopRecord(ids[static_cast<std::size_t>(l.query)], ids[static_cast<std::size_t>(l.candidate)],
                                 l.T, bench::kLoopSigmaM, bench::kLoopSigmaRad);
      if (mode != Mode::kKernel) r.probability = l.p;
      store->addLoop("m", r);
      if (k + 1 == first || (k + 1 > first && (k + 1 - first) % batch == 0)) graph.optimiseNow("m");
    }
    graph.optimiseNow("m", posegraph::GraphOptimiser::Scope::kGlobal);
    ate = bench::ateOf(*store, ids, gt);
    graph.stop();
  }
  fs::remove_all(o.dir);
  return ate;
}

nlohmann::ordered_json sequence(const Options& o, const std::string& seq) {
  const auto traj = trajectory(o, seq);
  std::vector<int> src(traj.poses.size());
  for (std::size_t i = 0; i < src.size(); ++i) src[i] = static_cast<int>(i);
  const auto odom = sim::driftingOdometry(traj.poses, src, sim::OdometryNoise{0.01, 0.005}, o.seed);
  sim::Rng rng(sim::hashKeys(o.seed, 0x100ULL));
  const auto truth = trueLoops(traj.poses, src, rng);
  nlohmann::ordered_json out;
  out["sequence"] = seq;
  out["trajectory"] = traj.source;
  out["frames"] = traj.poses.size();
  out["loops"] = truth.size();
  out["ate_odometry_m"] = bench::ate(odom, traj.poses);
  for (const double f : o.fractions) {
    auto loops = truth;
    sim::Rng frng(sim::hashKeys(o.seed, 0xF0ULL, static_cast<std::uint64_t>(f * 1000)));
    falsify(loops, traj.poses, f, o, frng);
    nlohmann::ordered_json row;
    row["false_percent"] = f;
    row["false_loops"] = std::count_if(loops.begin(), loops.end(), [](const Loop& l) { return !l.truth; });
    for (const auto mode : {Mode::kKernel, Mode::kProbability, Mode::kEquallyProbable}) {
      assignProbabilities(loops, mode, o);
      row[std::string("ate_") + modeName(mode) + "_m"] = run(traj.poses, odom, loops, mode, o);
      std::cerr << "sequence " << seq << ", " << f << " % false, " << modeName(mode) << ": ATE "
                << row[std::string("ate_") + modeName(mode) + "_m"].get<double>() << " m\n";
    }
    out["runs"].push_back(row);
  }
  return out;
}

void printMarkdown(const nlohmann::ordered_json& report) {
  std::cout
      << "| sequence | false loops | ATE kernel only (m) | ATE with p (m) | ATE, false as probable as true (m) |\n"
         "|---|---|---|---|---|\n";
  for (const auto& s : report["sequences"])
    for (const auto& r : s["runs"]) {
      char line[256];
      std::snprintf(line, sizeof line, "| %s | %.0f %% (%d of %d) | %.3f | %.3f | %.3f |\n",
                    s["sequence"].get<std::string>().c_str(), r["false_percent"].get<double>(),
                    r["false_loops"].get<int>(), s["loops"].get<int>(), r["ate_kernel_m"].get<double>(),
                    r["ate_probability_m"].get<double>(), r["ate_equal_probability_m"].get<double>());
      std::cout << line;
    }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ATE under false loops, with and without the loop probability in the pose graph (JSON on stdout)."};
  Options o;
  app.add_option("--dir", o.dir, "scratch directory (removed first)")->capture_default_str();
  app.add_option("--data", o.data, "shared data directory (KITTI ground-truth poses)")->capture_default_str();
  app.add_option("--seqs", o.seqs, "KITTI sequences (00, 05, 08)")->delimiter(',')->capture_default_str();
  app.add_option("--fractions", o.fractions, "percent of loops made false")->delimiter(',')->capture_default_str();
  app.add_option("--events", o.events, "loop batches after the cold solve")->check(CLI::Range(1, 1000));
  app.add_option("--seed", o.seed, "seed of every draw")->check(CLI::Range(0, 99))->capture_default_str();
  app.add_option("--false-p-min", o.false_p_min, "false loops' probability, from")->check(CLI::Range(0.0, 1.0));
  app.add_option("--false-p-max", o.false_p_max, "to")->check(CLI::Range(0.0, 1.0));
  app.add_option("--false-off-min", o.off_min_m, "false loops are this far off at least (m)")
      ->check(CLI::Range(0.0, 1e5))
      ->capture_default_str();
  app.add_option("--false-off-max", o.off_max_m, "and at most (m)")->check(CLI::Range(0.0, 1e5))->capture_default_str();
  app.add_option("--trusted", o.trusted, "pose_graph.trusted_probability")->check(CLI::Range(0.0, 1.0));
  app.add_flag("--markdown", o.markdown, "print a table instead of JSON");
  CLI11_PARSE(app, argc, argv);
  spdlog::set_default_logger(spdlog::stderr_logger_st("bench"));
  spdlog::set_level(spdlog::level::warn);
  try {
    for (const double f : o.fractions)
      if (!(f >= 0 && f <= 100)) throw InputError("--fractions: percentages in [0, 100]");
    if (o.false_p_min > o.false_p_max) throw InputError("--false-p-min is above --false-p-max");
    if (o.off_min_m > o.off_max_m) throw InputError("--false-off-min is above --false-off-max");
    nlohmann::ordered_json report;
    report["seed"] = o.seed;
    report["trusted_probability"] = o.trusted;
    report["false_probability"] = {o.false_p_min, o.false_p_max};
    report["false_offset_m"] = {o.off_min_m, o.off_max_m};
    for (const auto& seq : o.seqs) report["sequences"].push_back(sequence(o, seq));
    if (o.markdown)
      printMarkdown(report);
    else
      std::cout << report.dump(2) << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "sglc-bench-false-loops: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
