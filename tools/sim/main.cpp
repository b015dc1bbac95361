// sglc-sim: renders a labelled LiDAR sequence along a KITTI trajectory (or the built-in loop route) and writes
// it in the SemanticKITTI layout with ground truth. See tools/sim/README.md.
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>
#include <thread>

#include "common/finite_options.hpp"
#include "sglc/frame_selection.hpp"
#include "sglc/version.hpp"
#include "sim/sensor.hpp"
#include "sim/sequence.hpp"

namespace {

// The command line. Negative (and 1e9 for the field of view) means "not given": the preset's value applies.
struct Options {
  std::string poses_path, calib_path, route, frames_spec, out_dir, sensor;
  std::uint64_t seed = 7;
  double label_noise = 0.0, label_confusion = -1, label_bleed = -1, label_miss = -1;
  std::string label_model;              // "" (not given), "iid" or "network"
  std::vector<CLI::Option*> iid_knobs;  // --label-noise and its overrides: given ones exclude the network model
  int beams = -1, columns = 0, threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  double max_range = 0.0, range_noise = -1.0, odom_noise = 0.0, odom_rot = -1.0;
  double fov_up = 1e9, fov_down = 1e9;
  bool noise_free = false, no_moving = false, quiet = false, overwrite = false;
  bool laser_offsets = false, motion_distortion = false, realistic = false;
  double mixed_pixels = 0.0;
  CLI::Option* mixed_pixels_option = nullptr;
  int epoch = 0;  // with epoch_option not given: the frozen world (or day 0 with --turnover)
  CLI::Option* epoch_option = nullptr;
  bool turnover = false;
  double aliasing = 0.0;
  sglc::sim::PairListConfig pairs;
};

void addInputOptions(CLI::App& app, Options& o) {
  app.add_option("--poses", o.poses_path, "KITTI ground-truth poses file (camera frame, 12 numbers per line)");
  app.add_option("--calib", o.calib_path, "calib.txt whose Tr line converts the poses to the LiDAR frame");
  app.add_option("--route", o.route, "Built-in route instead of --poses")->check(CLI::IsMember({"loop"}));
  app.add_option("--frames", o.frames_spec, "Frames: comma-separated a:b (b exclusive) or a:b:s ranges; default all");
  app.add_option("--seed", o.seed, "World and noise seed")->capture_default_str();
  app.add_option("--out", o.out_dir, "Output directory (SemanticKITTI sequence layout)");
}

void addLabelNoiseOptions(CLI::App& app, Options& o) {
  o.iid_knobs = {
      app.add_option("--label-noise", o.label_noise, "Network-like label noise rate (0 = ground-truth labels)")
          ->capture_default_str()
          ->check(CLI::Range(0.0, 1.0)),
      app.add_option("--label-confusion", o.label_confusion, "Override: class confusion rate")
          ->check(CLI::Range(0.0, 1.0)),
      app.add_option("--label-bleed", o.label_bleed, "Override: boundary bleed probability")
          ->check(CLI::Range(0.0, 1.0)),
      app.add_option("--label-miss", o.label_miss, "Override: chance to miss a small object")
          ->check(CLI::Range(0.0, 1.0))};
  app.add_option("--label-noise-model", o.label_model,
                 "iid: the --label-noise knobs (default); network: errors calibrated to RangeNet53++'s per-class "
                 "IoU on SemanticKITTI (no other label option with it)")
      ->check(CLI::IsMember({"iid", "network"}));
}

void addSensorOptions(CLI::App& app, Options& o) {
  app.add_option("--sensor", o.sensor, "Sensor preset: vlp16, hdl32, hdl64 (default), os1-128 or rosette (Livox-like)")
      ->check(CLI::IsMember(sglc::sim::sensorPresetNames()));
  app.add_option("--beams", o.beams, "64 (HDL-64E-like, default), 32, 128, or any count spread over +2..-24.8 deg");
  app.add_option("--columns", o.columns, "Azimuth steps per revolution (default: the preset's)")
      ->check(CLI::Range(8, 65535));
  app.add_option("--fov-up", o.fov_up, "Elevation of the top beam in deg (with --fov-down: beams spread evenly)")
      ->check(CLI::Range(-90.0, 90.0));
  app.add_option("--fov-down", o.fov_down, "Elevation of the bottom beam in deg")->check(CLI::Range(-90.0, 90.0));
  app.add_option("--range", o.max_range, "Maximum range in m (default: the preset's)")->check(CLI::PositiveNumber);
  app.add_option("--range-noise", o.range_noise, "Range noise sigma in m (default 0.02)")->check(CLI::Range(0.0, 10.0));
  app.add_flag("--noise-free", o.noise_free, "No range noise, dropouts or intensity noise");
  app.add_flag("--no-moving", o.no_moving, "No moving vehicles or pedestrians");
}

void addRealismOptions(CLI::App& app, Options& o) {
  app.add_flag("--laser-offsets", o.laser_offsets,
               "Per-laser calibration errors (elevation, azimuth, range bias) drawn from the seed");
  app.add_flag("--realistic", o.realistic,
               "The field preset: --label-noise-model network, --turnover, --laser-offsets and --mixed-pixels 0.5 "
               "(each of the last two may still be given; the label knobs may not)");
  o.mixed_pixels_option =
      app.add_option("--mixed-pixels", o.mixed_pixels,
                     "Chance that a return beside a > 1 m depth edge blends the two ranges (0 = off; try 0.5)")
          ->capture_default_str()
          ->check(CLI::Range(0.0, 1.0));
  app.add_flag("--motion-distortion", o.motion_distortion,
               "Cast each column / ray from the pose at its own time in the sweep (raw, not de-skewed scans)");
}

void addWorldOptions(CLI::App& app, Options& o) {
  // Checked in validate(), so that the error names the flag and the bad value plainly.
  o.epoch_option =
      app.add_option("--epoch", o.epoch,
                     "Render the world N >= 0 days after today: parked cars, temporary objects and foliage change "
                     "(implies --turnover)");
  app.add_flag("--turnover", o.turnover,
               "Parked cars come and go during the run, temporary objects follow their epoch (day 0 unless --epoch)");
  app.add_option("--aliasing", o.aliasing, "Share of lots (0..1) copied from a few templates: look-alike streets")
      ->capture_default_str();
}

void addOutputOptions(CLI::App& app, Options& o) {
  app.add_option("--odom-noise", o.odom_noise,
                 "Write odometry.txt with drift: translation sigma as a fraction of distance (e.g. 0.01)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--odom-rot-noise", o.odom_rot, "Odometry yaw sigma in deg per m (default 0.5 * --odom-noise)")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--min-gap", o.pairs.min_gap, "Loop pairs need trajectory frames more than this apart")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--neg-ratio", o.pairs.negatives_per_positive, "Sampled negatives per positive in pairs_distance.txt")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--threads", o.threads, "Frames rendered in parallel (output does not depend on it)")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  app.add_flag("--overwrite", o.overwrite, "Replace the scans of an earlier run in --out (refused otherwise)");
  app.add_flag("--quiet", o.quiet, "No progress lines");
}

void addOptions(CLI::App& app, Options& o) {
  addInputOptions(app, o);
  addLabelNoiseOptions(app, o);
  addSensorOptions(app, o);
  addRealismOptions(app, o);
  addWorldOptions(app, o);
  addOutputOptions(app, o);
}

// What is wrong with a parsed command line, or "" when nothing is.
std::string validate(const Options& o) {
  if (o.poses_path.empty() == o.route.empty()) return "give either --poses (with --calib) or --route loop";
  if (!o.poses_path.empty() && o.calib_path.empty())
    return "--calib is required with --poses (KITTI poses are in the camera frame; its Tr converts them)";
  if (!o.route.empty() && !o.calib_path.empty()) return "--calib applies to --poses only, not to --route";
  if ((o.fov_up < 1e9) != (o.fov_down < 1e9)) return "--fov-up and --fov-down go together";
  if (o.fov_up < 1e9 && o.fov_up <= o.fov_down) return "--fov-up must be above --fov-down";
  if (!o.sensor.empty() && o.beams >= 0)
    return "--sensor and --beams are mutually exclusive (--sensor picks the beam layout; give one of them)";
  if (o.sensor == "rosette" && (o.columns > 0 || o.fov_up < 1e9))
    return "--columns, --fov-up and --fov-down do not apply to --sensor rosette (it has no columns or beams)";
  if (o.epoch_option->count() > 0 && o.epoch < 0)
    return "--epoch must be a whole number of days >= 0, got " + std::to_string(o.epoch);
  if (!(o.aliasing >= 0.0 && o.aliasing <= 1.0))
    return "--aliasing must be within [0, 1], got " + std::to_string(o.aliasing);
  if (o.out_dir.empty()) return "--out is required";
  if (o.realistic && o.label_model == "iid") return "--realistic uses --label-noise-model network; give one of them";
  if (o.realistic || o.label_model == "network")
    for (const CLI::Option* knob : o.iid_knobs)
      if (knob->count() > 0)
        return std::string(o.realistic ? "--realistic" : "--label-noise-model network") +
               " uses the calibrated network label noise and cannot be mixed with " + knob->get_name() +
               " (that knob belongs to --label-noise-model iid)";
  return "";
}

// --realistic: what a robot in the street sees, rather than the lab (tools/sim/README.md, "Realistic preset").
void applyRealistic(Options& o) {
  if (!o.realistic) return;
  o.label_model = "network";
  o.turnover = true;
  o.laser_offsets = true;
  if (o.mixed_pixels_option->count() == 0) o.mixed_pixels = 0.5;
}

sglc::sim::SequenceOptions sequenceOptions(const Options& o, const sglc::sim::Trajectory& traj) {
  sglc::sim::SequenceOptions opt;
  opt.frames = sglc::FrameSelection::parse(o.frames_spec).frames(static_cast<int>(traj.poses.size()));
  opt.selection_spec = o.frames_spec;
  opt.out_dir = o.out_dir;
  opt.threads = o.threads;
  opt.overwrite = o.overwrite;
  opt.pairs = o.pairs;
  opt.pairs.seed = o.seed;
  opt.odometry.translation = o.odom_noise;
  opt.odometry.rotation_deg_per_m = o.odom_rot >= 0 ? o.odom_rot : 0.5 * o.odom_noise;
  return opt;
}

sglc::sim::SensorConfig sensorConfig(const Options& o) {
  auto sensor = !o.sensor.empty() ? sglc::sim::sensorPreset(o.sensor)
                                  : sglc::sim::SensorConfig::preset(o.beams >= 0 ? o.beams : 64);
  if (o.columns > 0) sensor.columns = o.columns;
  if (o.fov_up < 1e9) {
    const int n = sensor.beams();
    sensor.name += "-fov";
    for (int k = 0; k < n; ++k)
      sensor.elevation_deg[k] =
          n == 1 ? 0.5 * (o.fov_up + o.fov_down) : o.fov_up - k * (o.fov_up - o.fov_down) / (n - 1);
  }
  if (o.max_range > 0) sensor.max_range = o.max_range;
  if (o.noise_free) sensor.noiseFree();
  if (o.range_noise >= 0) sensor.range_noise = o.range_noise;
  sensor.laser_offsets = o.laser_offsets;
  sensor.mixed_pixel_rate = o.mixed_pixels;
  sensor.motion_distortion = o.motion_distortion;
  return sensor;
}

sglc::sim::SimConfig simConfig(const Options& o) {
  sglc::sim::SimConfig cfg;
  cfg.seed = o.seed;
  cfg.sensor = sensorConfig(o);
  cfg.world.moving_objects = !o.no_moving;
  cfg.world.turnover = o.turnover || o.epoch_option->count() > 0;
  cfg.world.epoch = std::max(0, o.epoch);
  cfg.world.aliasing = o.aliasing;
  if (o.label_model == "network") {
    cfg.label_noise = sglc::sim::LabelNoise::network();
    return cfg;
  }
  cfg.label_noise = sglc::sim::LabelNoise::fromRate(o.label_noise);
  if (o.label_confusion >= 0) cfg.label_noise.confusion = o.label_confusion;
  if (o.label_bleed >= 0) cfg.label_noise.bleed = o.label_bleed;
  if (o.label_miss >= 0) cfg.label_noise.miss = o.label_miss;
  return cfg;
}

// A progress line on stderr at most every 2 s, and one at the end.
std::function<void(int, int, double)> progressPrinter() {
  return [last = -10.0](int done, int total, double secs) mutable {
    if (secs - last < 2.0 && done < total) return;
    last = secs;
    char buf[160];
    const double fps = done / std::max(secs, 1e-9);
    std::snprintf(buf, sizeof buf, "sglc-sim: %d/%d frames (%.0f%%), %.1f frames/s, %.0f s left", done, total,
                  100.0 * done / total, fps, fps > 0 ? (total - done) / fps : 0.0);
    std::cerr << buf << std::endl;
  };
}

// The IoU of the written labels against the true ones: mIoU and the classes present.
void printLabelIou(const sglc::sim::LabelIouCounts& iou) {
  std::string classes;
  char buf[64];
  for (int k = 0; k < sglc::sim::kEvalClasses; ++k) {
    if (!iou.present(k)) continue;
    std::snprintf(buf, sizeof buf, "%s%s %.2f", classes.empty() ? "" : ", ", sglc::sim::kEvalClassTable[k].name,
                  iou.iou(k));
    classes += buf;
  }
  std::printf("  labels:       mIoU %.3f vs true labels (%s)\n", iou.meanIou(), classes.c_str());
}

// The summary on stdout.
void printReport(const Options& o, const sglc::sim::Simulator& sim, const sglc::sim::SequenceSummary& s) {
  rusage usage_info{};
  getrusage(RUSAGE_SELF, &usage_info);
  const auto& sc = sim.config().sensor;
  const auto& noise = sim.config().label_noise;
  const auto& ws = sim.world().stats();
  char buf[512];
  std::printf("sglc-sim: wrote %d frames to %s\n", s.frames, o.out_dir.c_str());
  std::printf("  trajectory:   %s, %d frames, selection '%s'\n", sim.trajectory().source.c_str(), sim.numFrames(),
              o.frames_spec.empty() ? "all" : o.frames_spec.c_str());
  if (sc.isRosette())
    std::printf("  sensor:       %s, %d rays per frame (%d x %d pseudo image), %.0f m", sc.name.c_str(),
                sc.rosette_rays, sc.beams(), sc.columns, sc.max_range);
  else
    std::printf("  sensor:       %s, %d beams x %d columns, %.0f m", sc.name.c_str(), sc.beams(), sc.columns,
                sc.max_range);
  std::printf("%s%s%s", sc.laser_offsets ? ", laser offsets" : "", sc.mixed_pixel_rate > 0 ? ", mixed pixels" : "",
              sc.motion_distortion ? ", motion distortion" : "");
  if (noise.model == sglc::sim::LabelNoiseModel::kNetwork)
    std::printf("; label noise: network (RangeNet53++ calibrated)\n");
  else
    std::printf("; label noise: confusion %.3f, bleed %.3f, miss %.3f\n", noise.confusion, noise.bleed, noise.miss);
  std::snprintf(buf, sizeof buf,
                "  world:        seed %llu, %.0f m of street, %zu primitives (%zu buildings, %zu trees, %zu poles, "
                "%zu signs, %zu parked vehicles, %zu moving agents), %.1f MB, built in %.2f s\n",
                static_cast<unsigned long long>(o.seed), ws.path_length_m, ws.primitives, ws.buildings, ws.trees,
                ws.poles, ws.signs, ws.parked_vehicles, ws.moving_agents, ws.memory_bytes / 1e6, ws.build_seconds);
  std::fputs(buf, stdout);
  printLabelIou(s.label_iou);
  const auto& wc = sim.config().world;
  if (wc.turnover || wc.aliasing > 0)
    std::printf(
        "  time:         %s day %d: %zu parking slots, %zu temporary-object sites; aliasing %.2f: %zu "
        "look-alike lots\n",
        wc.turnover ? "turnover on," : "frozen,", wc.epoch, ws.parking_slots, ws.temporary_sites, wc.aliasing,
        ws.aliased_lots);
  std::printf("  points:       %.0f per frame, %.1f MB written\n", static_cast<double>(s.points) / s.frames,
              s.bytes / 1e6);
  std::printf("  speed:        %.1f frames/s (rendering and writing, %d worker threads), %.2f s\n", s.frames_per_second,
              o.threads, s.seconds);
  std::printf(
      "  ground truth: %zu loop pairs + %zu negatives in pairs_distance.txt; %zu loop_distance4 rows (%zu reverse)\n",
      s.positives, s.negatives, s.loop_rows, s.reverse_loop_rows);
  std::printf("  peak memory:  %.0f MB\n", usage_info.ru_maxrss / 1024.0);
}

// Builds the world, renders and writes the sequence, prints the summary.
void run(const Options& o) {
  sglc::sim::Trajectory traj =
      o.route.empty() ? sglc::sim::loadKittiTrajectory(o.poses_path, o.calib_path) : sglc::sim::loopRoute();
  sglc::sim::SequenceOptions opt = sequenceOptions(o, traj);
  const sglc::sim::SimConfig cfg = simConfig(o);
  if (!o.quiet)
    std::cerr << "sglc-sim: building the world around " << traj.poses.size() << " poses (" << traj.source << ")"
              << std::endl;
  const sglc::sim::Simulator sim(std::move(traj), cfg);
  if (!o.quiet)
    std::cerr << "sglc-sim: world ready in " << sim.world().stats().build_seconds << " s; rendering "
              << opt.frames.size() << " frames with " << o.threads << " threads" << std::endl;
  if (!o.quiet) opt.progress = progressPrinter();
  const auto summary = sglc::sim::writeSequence(sim, opt);
  printReport(o, sim, summary);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Labelled LiDAR simulator: drives a virtual spinning LiDAR through a procedural, seeded urban world built "
      "around a trajectory, and writes velodyne/*.bin, labels/*.label, poses.txt, calib.txt and loop ground truth."};
  app.set_version_flag("--version", std::string("sglc-sim ") + sglc::kVersion);
  Options options;
  addOptions(app, options);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "sglc-sim: error: " << e.what() << " (see --help)" << std::endl;
    return 2;
  }
  std::string problem = sglc::tools::nonFiniteValue(app);
  if (problem.empty()) problem = validate(options);
  if (!problem.empty()) {
    std::cerr << "sglc-sim: error: " << problem << " (see --help)" << std::endl;
    return 2;
  }
  applyRealistic(options);
  try {
    run(options);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sglc-sim: error: " << e.what() << std::endl;
    return 1;
  }
}
