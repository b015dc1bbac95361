// sglc-eval: loop-closure metrics computed the way the paper's protocols define them (docs/METHOD.md),
// on a SemanticKITTI-layout sequence or on a simulated one, with the engine in-process or through a server.
//
//   sglc-eval --protocol pairs|sequence|pose|all|slam [--data DIR | --sim [--poses P --calib C] [--seed N]
//             [--label-noise X]] [--frames SPEC] [--pairs FILE] [--pose-pairs FILE] [--server ADDR] --out DIR
//
// "all" runs the sequence protocol, then the pair and pose protocols on the frames it stored (each frame is
// rendered and fingerprinted once), into DIR/sequence, DIR/pairs and DIR/pose. With --sim, the pair and pose
// protocols take their pairs from the simulator's ground truth unless files are given.
//
// Writes DIR/summary.json and, through tools/eval/plot.py, the figures (pr_curve.png, trajectory.png,
// pose_errors.png) from the CSV files it writes beside them.
#include <unistd.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "common/finite_options.hpp"
#include "progress.hpp"
#include "protocols.hpp"
#include "sglc/config/engine_file.hpp"
#include "sglc/version.hpp"

#ifndef SGLC_EVAL_PLOT_SCRIPT
#define SGLC_EVAL_PLOT_SCRIPT "tools/eval/plot.py"
#endif

namespace {

namespace fs = std::filesystem;
using namespace sglc;
using namespace sglc::eval;

// Frames more than this apart make a loop pair in the lists derived from the simulator (sglc-sim's --min-gap).
constexpr int kSimPairMinGap = 50;
// 3-D distance below which a loop pair gets a pose row (sglc-sim's loop_distance4.txt).
constexpr double kSimPoseMaxM = 4.0;

// sglc-eval reads every cloud of a bag unless told otherwise.
BagDriveOptions everyCloud() {
  BagDriveOptions o;
  o.keyframe_m = o.keyframe_deg = 0;
  return o;
}

struct Options {
  std::string protocol, data, map_data, poses, calib, frames, pairs, pose_pairs, server, token, out, config_path,
      gt_list, title;
  bool sim = false, no_plots = false, gt_from_file = false, no_labels = false, keep_maps = false, no_deskew = false;
  std::string deskew_motion = "next";
  int beams = 64;
  std::uint64_t seed = 7;
  double label_noise = 0, positive_m = 3.0, negative_m = 20.0;
  int threads = 2;
  BagDriveOptions bag = everyCloud();
  LoopQuery query;
  SlamOptions slam;
};

void addSourceOptions(CLI::App& app, Options& o) {
  app.add_option("--data", o.data,
                 "SemanticKITTI-layout sequence directory (velodyne/, labels/, poses.txt, calib.txt)");
  app.add_flag("--sim", o.sim, "render a simulated sequence in memory");
  app.add_option("--map-data", o.map_data,
                 "relocalization: the drive the map is built from (SemanticKITTI layout, poses in --data's world)");
  app.add_option("--poses", o.poses, "with --sim: KITTI poses file to follow (default: the built-in route)");
  app.add_option("--calib", o.calib, "with --sim --poses: KITTI calib.txt (Tr)");
  app.add_option("--seed", o.seed, "with --sim: world and sensor seed (also samples the derived negative pairs)")
      ->capture_default_str();
  app.add_option("--label-noise", o.label_noise, "with --sim: label noise rate (0..1)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--beams", o.beams, "with --sim: sensor with 32 (HDL-32E-like), 64 (HDL-64E-like) or 128 beams")
      ->capture_default_str()
      ->check(CLI::IsMember({32, 64, 128}));
  app.add_flag("--no-labels", o.no_labels,
               "send points only (labels removed from any source): the engine's labeller labels them");
  app.add_option("--frames", o.frames, "frame selection 'a:b:s,...' (default: all)");
  app.add_option("--points-topic", o.bag.points_topic,
                 "--data is a bag (MCAP, .db3, rosbag2 directory, ROS 1 .bag): "
                 "its PointCloud2 topic");
  app.add_option("--odom-topic", o.bag.odom_topic, "... its Odometry topic (the poses the protocols compare with)");
  app.add_option("--tf", o.bag.tf_frame, "... or the fixed frame to look the clouds up in over /tf");
  app.add_option("--keyframe-m", o.bag.keyframe_m, "... a cloud every this many metres (0: every cloud)")
      ->capture_default_str();
  app.add_option("--keyframe-deg", o.bag.keyframe_deg, "... or degrees of turn")->capture_default_str();
  app.add_flag("--no-deskew", o.no_deskew,
               "read scans with point_times/ as they are (default: de-skewed with the motion to the next frame)");
  app.add_option("--deskew-motion", o.deskew_motion,
                 "the motion scans with point_times/ are de-skewed with: next (the next frame's pose) or keyframe "
                 "(as the server does: constant velocity from the previous selected frame)")
      ->check(CLI::IsMember({"next", "keyframe"}))
      ->capture_default_str();
}

DeskewMotion deskewMotion(const Options& o) {
  if (o.no_deskew) return DeskewMotion::kOff;
  return o.deskew_motion == "keyframe" ? DeskewMotion::kPreviousKeyframe : DeskewMotion::kNextFrame;
}

void addProtocolOptions(CLI::App& app, Options& o) {
  app.add_option("--pairs", o.pairs,
                 "pair file: 'i j label' (pairs), 'i j [T 3x4]' (pose); with --sim: default the simulator's truth");
  app.add_option("--pose-pairs", o.pose_pairs, "with --protocol all: the pose protocol's pair file");
  app.add_option("--gt-list", o.gt_list, "sequence: true loops from this pair file instead of distances");
  app.add_flag("--gt-from-pairs", o.gt_from_file, "pose: ground truth from the pair file's T (maps i into j)");
  app.add_option("--positive-m", o.positive_m, "sequence: a true loop is closer than this (m)")->capture_default_str();
  app.add_option("--negative-m", o.negative_m, "sequence: a false loop is farther than this (m); between: ignored")
      ->capture_default_str();
  app.add_option("--exclude-recent", o.query.exclude_recent, "sequence: skip this many most recent frames")
      ->capture_default_str();
  app.add_option("--candidates", o.query.candidates,
                 "sequence: descriptor neighbours verified per query (at least 1% of frames)")
      ->capture_default_str();
  app.add_option("--odom-noise", o.slam.odom_noise, "slam: odometry drift (translation sigma per metre; 0.01 = 1 %)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.2));
  app.add_option("--robots", o.slam.robots, "slam: 1, or 2 robots on overlapping parts of the path")
      ->capture_default_str()
      ->check(CLI::IsMember({1, 2}));
}

void addRunOptions(CLI::App& app, Options& o) {
  app.add_option("--server", o.server, "measure a running sglc-server instead of the in-process engine");
  app.add_option("--token", o.token, "bearer token for --server");
  app.add_flag("--keep-maps", o.keep_maps,
               "with --server: leave the maps this run creates (default: deleted at the end)");
  app.add_option("--config", o.config_path, "engine configuration (YAML, as sglc-pair --config)");
  app.add_option("--threads", o.threads, "frames loaded or rendered ahead")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--title", o.title, "figure title");
  app.add_flag("--no-plots", o.no_plots, "write summary.json and the CSV files only");
  app.add_option("--out", o.out, "output directory")->required();
}

// Mistakes in the command line, found before any frame is read.
void validate(const Options& o) {
  if (o.sim == !o.data.empty()) throw InputError("give exactly one of --data DIR and --sim");
  if (!o.sim && (!o.poses.empty() || !o.calib.empty() || o.label_noise > 0 || o.beams != 64))
    throw InputError("--poses, --calib, --label-noise and --beams belong to --sim");
  if (o.no_labels && o.label_noise > 0) throw InputError("--label-noise has no effect with --no-labels");
  if ((o.protocol == "relocalization") != !o.map_data.empty())
    throw InputError("--protocol relocalization and --map-data DIR go together");
  if (o.protocol == "relocalization" && o.sim)
    throw InputError("--protocol relocalization reads two drives: give --map-data DIR and --data DIR");
  if (o.protocol == "slam" && o.server.empty())
    throw InputError("--protocol slam measures a server's pose graph: give --server ADDR");
  if (!o.sim && (o.protocol == "pairs" || o.protocol == "pose" || o.protocol == "all") && o.pairs.empty())
    throw InputError("--protocol " + o.protocol + " needs --pairs FILE (with --sim, the simulator's truth is used)");
  if (!o.sim && o.protocol == "all" && o.pose_pairs.empty())
    throw InputError("--protocol all needs --pose-pairs FILE (with --sim, the simulator's truth is used)");
  if (o.query.exclude_recent < 0 || o.query.candidates < 1 || o.query.candidates > 100)
    throw InputError("--exclude-recent must be >= 0 and --candidates 1..100");
  if (!(o.positive_m > 0) || !std::isfinite(o.negative_m))
    throw InputError("--positive-m must be a positive distance and --negative-m a finite one (m)");
  const bool derived_pairs = o.sim && o.pairs.empty() && (o.protocol == "pairs" || o.protocol == "all");
  if ((o.protocol == "sequence" || o.protocol == "all" || o.protocol == "relocalization" || derived_pairs) &&
      !(o.negative_m >= o.positive_m))
    throw InputError("--negative-m must be >= --positive-m");
}

std::unique_ptr<FrameSource> makeSource(const Options& o) {
  auto source = o.sim ? simulatedSource({o.poses, o.calib, o.frames, o.seed, o.label_noise, o.beams})
                      : directorySource(o.data, o.frames, deskewMotion(o), o.bag);
  if (o.no_labels) source = withoutLabels(std::move(source));
  return source;
}

// The relocalization protocol's map drive (every frame), or none.
std::unique_ptr<FrameSource> makeMapSource(const Options& o) {
  if (o.map_data.empty()) return nullptr;
  auto source = directorySource(o.map_data, "", deskewMotion(o), o.bag);
  if (o.no_labels) source = withoutLabels(std::move(source));
  return source;
}

// The pair list of the pair protocol (pose: false) or the pose protocol (pose: true), and where it came from.
std::pair<std::vector<PairRow>, std::string> pairList(const Options& o, const FrameSource& source, bool pose) {
  const std::string& file = pose && o.protocol == "all" ? o.pose_pairs : o.pairs;
  if (!file.empty()) return {readPairs(file), file};
  std::ostringstream from;
  from << "simulator ground truth: ";
  if (pose) {
    from << "loops with 3-D distance < " << kSimPoseMaxM << " m, frames more than " << kSimPairMinGap << " apart";
    return {posePairs(source, kSimPoseMaxM, kSimPairMinGap), from.str()};
  }
  from << "loops with horizontal distance < " << o.positive_m << " m, frames more than " << kSimPairMinGap
       << " apart; non-loops > " << o.negative_m << " m, sampled with seed " << o.seed;
  return {distancePairs(source, {o.positive_m, o.negative_m, kSimPairMinGap, o.seed}), from.str()};
}

// The run's settings, in every protocol's summary.json.
void describe(Run& run, const Options& o, const std::string& name, const std::string& map_name, const Config& config) {
  auto& s = run.summary;
  s["protocol"] = name;
  s["title"] = (o.title.empty() ? name : o.title + " - " + name) + ": " + run.source.describe();
  s["source"] = run.source.describe();
  s["backend"] = run.backend.name();
  s["labels_sent"] = o.no_labels ? "none" : "given";
  if (o.server.empty()) {  // a server's own configuration decides there (GetServerInfo)
    s["label_preset"] = config.labels.preset;
    s["labeller_mode"] = config.labeller.mode;
  }
  if (o.sim) s["beams"] = o.beams;
  if (!o.server.empty()) {
    s["server_map"] = map_name;
    s["server_map_kept"] = o.keep_maps;
  }
  s["frames"] = run.source.frames().size();
  if (name == "relocalization") s["candidates"] = o.query.candidates;
  if (name != "sequence") return;
  s["exclude_recent"] = o.query.exclude_recent;
  s["candidates"] = o.query.candidates;
  if (o.gt_list.empty()) {
    s["positive_m"] = o.positive_m;
    s["negative_m"] = o.negative_m;
  } else {
    s["gt_list"] = o.gt_list;
  }
}

void runProtocol(Run& run, const Options& o, const std::string& name, const std::string& map_name,
                 const FrameSource* map_source) {
  if (name == "relocalization") {
    relocalizationProtocol(run, *map_source, o.query, {o.positive_m, o.negative_m, nullptr});
  } else if (name == "slam") {
    SlamOptions slam = o.slam;
    slam.server = o.server;
    slam.token = o.token;
    slam.map = map_name + "-slam";
    slam.seed = o.seed;
    slam.exclude_recent = o.query.exclude_recent;
    slam.keep_map = o.keep_maps;
    slamProtocol(run, slam);
  } else if (name == "pairs" || name == "pose") {
    const auto [rows, from] = pairList(o, run.source, name == "pose");
    run.summary["pairs_file"] = from;
    if (name == "pairs")
      pairProtocol(run, rows);
    else
      poseProtocol(run, rows, o.gt_from_file);
  } else {
    std::vector<PairRow> list;
    if (!o.gt_list.empty()) list = readPairs(o.gt_list);
    sequenceProtocol(run, o.query, {o.positive_m, o.negative_m, o.gt_list.empty() ? nullptr : &list});
  }
}

// summary.json, then the figures; false when plotting failed (the summary and CSV files are there).
bool writeOutputs(const Run& run, const Options& o, const std::string& dir) {
  {
    std::ofstream js(dir + "/summary.json");
    js << run.summary.dump(2) << "\n";
    if (!js) throw std::runtime_error(dir + "/summary.json: write failed");
  }
  if (o.no_plots) return true;
  const std::string cmd = "/usr/bin/python3 '" + std::string(SGLC_EVAL_PLOT_SCRIPT) + "' '" + dir + "' 1>&2";
  if (std::system(cmd.c_str()) == 0) return true;
  std::cerr << "sglc-eval: plotting failed (" << cmd << "); summary.json and the CSV files are written\n";
  return false;
}

int evaluate(Options& o) {
  validate(o);
  Config config;
  if (!o.config_path.empty()) config = loadConfig(o.config_path);
  if (o.no_labels && o.server.empty() && config.labeller.mode == "off")
    throw InputError("--no-labels needs the labeller: labeller.mode is off in --config");
  fs::create_directories(o.out);
  const auto source = makeSource(o);
  const auto map_source = makeMapSource(o);
  if (o.protocol == "sequence" || o.protocol == "all" || map_source) {  // at least 1 % of the frames searched
    const auto searched = (map_source ? map_source : source)->frames().size();
    const auto n = static_cast<int>(std::ceil(0.01 * static_cast<double>(searched)));
    o.query.candidates = std::min(100, std::max(o.query.candidates, n));
  }
  const std::string map_name = "eval-" + std::to_string(std::time(nullptr)) + "-" + std::to_string(::getpid());
  const auto backend = o.server.empty() ? inProcessBackend(config, o.out + "/scratch")
                                        : serverBackend(o.server, o.token, map_name, o.keep_maps);
  std::set<int> stored;
  // One invocation may run several protocols over the same stored frames ("all": sequence first, then
  // pairs and pose on what it stored), each into its own directory.
  const std::vector<std::string> protocols = o.protocol == "all" ? std::vector<std::string>{"sequence", "pairs", "pose"}
                                                                 : std::vector<std::string>{o.protocol};
  ordered_json combined;
  int status = 0;
  for (const auto& name : protocols) {
    const std::string dir = o.protocol == "all" ? o.out + "/" + name : o.out;
    fs::create_directories(dir);
    Run run{*source, *backend, o.threads, stored, {}, {}, dir};
    describe(run, o, name, map_name, config);
    const auto t0 = std::chrono::steady_clock::now();
    runProtocol(run, o, name, map_name, map_source.get());
    run.summary["wall_s"] = secondsSince(t0);
    run.summary["timings"] = run.timings.json();
    if (!writeOutputs(run, o, dir)) status = 3;
    combined[name] = run.summary;
  }
  if (o.server.empty()) fs::remove_all(o.out + "/scratch");
  if (o.protocol == "all") {
    std::ofstream js(o.out + "/summary.json");
    js << combined.dump(2) << "\n";
  }
  std::cout << (o.protocol == "all" ? combined : combined[o.protocol]).dump(2) << std::endl;
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Loop-closure evaluation: F1max, EP, AUC, Recall@1, registration recall, pose errors, timing."};
  app.set_version_flag("--version", std::string("sglc-eval ") + sglc::kVersion);
  Options o;
  app.add_option("--protocol", o.protocol,
                 "pairs, sequence, pose, all (sequence, then pairs and pose on the same frames), slam, or "
                 "relocalization (--data's frames query a map of --map-data's)")
      ->required()
      ->check(CLI::IsMember({"pairs", "sequence", "pose", "all", "slam", "relocalization"}));
  addSourceOptions(app, o);
  addProtocolOptions(app, o);
  addRunOptions(app, o);
  CLI11_PARSE(app, argc, argv);
  if (const std::string problem = sglc::tools::nonFiniteValue(app); !problem.empty()) {
    std::cerr << "sglc-eval: error: " << problem << std::endl;
    return 2;
  }
  try {
    return evaluate(o);
  } catch (const std::exception& e) {
    std::cerr << "sglc-eval: error: " << e.what() << std::endl;
    return 1;
  }
}
