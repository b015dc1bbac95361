// sglc-sim: renders a labelled LiDAR sequence along a KITTI trajectory (or the built-in loop route) and writes
// it in the SemanticKITTI layout with ground truth. See tools/sim/README.md.
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>
#include <thread>

#include "sglc/frame_selection.hpp"
#include "sim/sequence.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "Labelled LiDAR simulator: drives a virtual spinning LiDAR through a procedural, seeded urban world built "
      "around a trajectory, and writes velodyne/*.bin, labels/*.label, poses.txt, calib.txt and loop ground truth."};
  std::string poses_path, calib_path, route, frames_spec, out_dir;
  std::uint64_t seed = 7;
  double label_noise = 0.0, label_confusion = -1, label_bleed = -1, label_miss = -1;
  int beams = 64, columns = 0, threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  double max_range = 0.0, range_noise = -1.0, odom_noise = 0.0, odom_rot = -1.0;
  double fov_up = 1e9, fov_down = 1e9;
  bool noise_free = false, no_moving = false, quiet = false, overwrite = false;
  sglc::sim::PairListConfig pairs;
  app.add_option("--poses", poses_path, "KITTI ground-truth poses file (camera frame, 12 numbers per line)");
  app.add_option("--calib", calib_path, "calib.txt whose Tr line converts the poses to the LiDAR frame");
  app.add_option("--route", route, "Built-in route instead of --poses")->check(CLI::IsMember({"loop"}));
  app.add_option("--frames", frames_spec, "Frames: comma-separated a:b (b exclusive) or a:b:s ranges; default all");
  app.add_option("--seed", seed, "World and noise seed")->capture_default_str();
  app.add_option("--out", out_dir, "Output directory (SemanticKITTI sequence layout)");
  app.add_option("--label-noise", label_noise, "Network-like label noise rate (0 = ground-truth labels)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--label-confusion", label_confusion, "Override: class confusion rate")->check(CLI::Range(0.0, 1.0));
  app.add_option("--label-bleed", label_bleed, "Override: boundary bleed probability")->check(CLI::Range(0.0, 1.0));
  app.add_option("--label-miss", label_miss, "Override: chance to miss a small object")->check(CLI::Range(0.0, 1.0));
  app.add_option("--beams", beams, "64 (HDL-64E-like), 32, 128, or any count spread over +2..-24.8 deg")
      ->capture_default_str();
  app.add_option("--columns", columns, "Azimuth steps per revolution (default: the preset's)")
      ->check(CLI::Range(8, 65535));
  app.add_option("--fov-up", fov_up, "Elevation of the top beam in deg (with --fov-down: beams spread evenly)")
      ->check(CLI::Range(-90.0, 90.0));
  app.add_option("--fov-down", fov_down, "Elevation of the bottom beam in deg")->check(CLI::Range(-90.0, 90.0));
  app.add_option("--range", max_range, "Maximum range in m (default: the preset's)")->check(CLI::PositiveNumber);
  app.add_option("--range-noise", range_noise, "Range noise sigma in m (default 0.02)")->check(CLI::Range(0.0, 10.0));
  app.add_flag("--noise-free", noise_free, "No range noise, dropouts or intensity noise");
  app.add_flag("--no-moving", no_moving, "No moving vehicles or pedestrians");
  app.add_option("--odom-noise", odom_noise,
                 "Write odometry.txt with drift: translation sigma as a fraction of distance (e.g. 0.01)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--odom-rot-noise", odom_rot, "Odometry yaw sigma in deg per m (default 0.5 * --odom-noise)")
      ->check(CLI::Range(0.0, 10.0));
  app.add_option("--min-gap", pairs.min_gap, "Loop pairs need trajectory frames more than this apart")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--neg-ratio", pairs.negatives_per_positive, "Sampled negatives per positive in pairs_distance.txt")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--threads", threads, "Frames rendered in parallel (output does not depend on it)")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  app.add_flag("--overwrite", overwrite, "Replace the scans of an earlier run in --out (refused otherwise)");
  app.add_flag("--quiet", quiet, "No progress lines");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "sglc-sim: error: " << e.what() << " (see --help)" << std::endl;
    return 2;
  }
  auto usage = [](const std::string& msg) {
    std::cerr << "sglc-sim: error: " << msg << " (see --help)" << std::endl;
    return 2;
  };
  if (poses_path.empty() == route.empty()) return usage("give either --poses (with --calib) or --route loop");
  if (!poses_path.empty() && calib_path.empty())
    return usage("--calib is required with --poses (KITTI poses are in the camera frame; its Tr converts them)");
  if (!route.empty() && !calib_path.empty()) return usage("--calib applies to --poses only, not to --route");
  if ((fov_up < 1e9) != (fov_down < 1e9)) return usage("--fov-up and --fov-down go together");
  if (fov_up < 1e9 && fov_up <= fov_down) return usage("--fov-up must be above --fov-down");
  if (out_dir.empty()) return usage("--out is required");

  try {
    sglc::sim::Trajectory traj =
        route.empty() ? sglc::sim::loadKittiTrajectory(poses_path, calib_path) : sglc::sim::loopRoute();
    sglc::sim::SequenceOptions opt;
    opt.frames = sglc::FrameSelection::parse(frames_spec).frames(static_cast<int>(traj.poses.size()));
    opt.selection_spec = frames_spec;
    opt.out_dir = out_dir;
    opt.threads = threads;
    opt.overwrite = overwrite;
    pairs.seed = seed;
    opt.pairs = pairs;
    opt.odometry.translation = odom_noise;
    opt.odometry.rotation_deg_per_m = odom_rot >= 0 ? odom_rot : 0.5 * odom_noise;

    sglc::sim::SimConfig cfg;
    cfg.seed = seed;
    cfg.sensor = sglc::sim::SensorConfig::preset(beams);
    if (columns > 0) cfg.sensor.columns = columns;
    if (fov_up < 1e9) {
      const int n = cfg.sensor.beams();
      cfg.sensor.name += "-fov";
      for (int k = 0; k < n; ++k)
        cfg.sensor.elevation_deg[k] = n == 1 ? 0.5 * (fov_up + fov_down) : fov_up - k * (fov_up - fov_down) / (n - 1);
    }
    if (max_range > 0) cfg.sensor.max_range = max_range;
    if (noise_free) cfg.sensor.noiseFree();
    if (range_noise >= 0) cfg.sensor.range_noise = range_noise;
    cfg.world.moving_objects = !no_moving;
    cfg.label_noise = sglc::sim::LabelNoise::fromRate(label_noise);
    if (label_confusion >= 0) cfg.label_noise.confusion = label_confusion;
    if (label_bleed >= 0) cfg.label_noise.bleed = label_bleed;
    if (label_miss >= 0) cfg.label_noise.miss = label_miss;

    if (!quiet)
      std::cerr << "sglc-sim: building the world around " << traj.poses.size() << " poses (" << traj.source << ")"
                << std::endl;
    const sglc::sim::Simulator sim(std::move(traj), cfg);
    const auto& ws = sim.world().stats();
    if (!quiet)
      std::cerr << "sglc-sim: world ready in " << ws.build_seconds << " s; rendering " << opt.frames.size()
                << " frames with " << threads << " threads" << std::endl;
    double last = -10.0;
    if (!quiet)
      opt.progress = [&](int done, int total, double secs) {
        if (secs - last < 2.0 && done < total) return;
        last = secs;
        char buf[160];
        const double fps = done / std::max(secs, 1e-9);
        std::snprintf(buf, sizeof buf, "sglc-sim: %d/%d frames (%.0f%%), %.1f frames/s, %.0f s left", done, total,
                      100.0 * done / total, fps, fps > 0 ? (total - done) / fps : 0.0);
        std::cerr << buf << std::endl;
      };
    const auto s = sglc::sim::writeSequence(sim, opt);

    rusage usage_info{};
    getrusage(RUSAGE_SELF, &usage_info);
    const auto& sc = sim.config().sensor;
    char buf[512];
    std::printf("sglc-sim: wrote %d frames to %s\n", s.frames, out_dir.c_str());
    std::printf("  trajectory:   %s, %d frames, selection '%s'\n", sim.trajectory().source.c_str(), sim.numFrames(),
                frames_spec.empty() ? "all" : frames_spec.c_str());
    std::printf(
        "  sensor:       %s, %d beams x %d columns, %.0f m; label noise: confusion %.3f, bleed %.3f, miss %.3f\n",
        sc.name.c_str(), sc.beams(), sc.columns, sc.max_range, cfg.label_noise.confusion, cfg.label_noise.bleed,
        cfg.label_noise.miss);
    std::snprintf(buf, sizeof buf,
                  "  world:        seed %llu, %.0f m of street, %zu primitives (%zu buildings, %zu trees, %zu poles, "
                  "%zu signs, %zu parked vehicles, %zu moving agents), %.1f MB, built in %.2f s\n",
                  static_cast<unsigned long long>(seed), ws.path_length_m, ws.primitives, ws.buildings, ws.trees,
                  ws.poles, ws.signs, ws.parked_vehicles, ws.moving_agents, ws.memory_bytes / 1e6, ws.build_seconds);
    std::fputs(buf, stdout);
    std::printf("  points:       %.0f per frame, %.1f MB written\n", static_cast<double>(s.points) / s.frames,
                s.bytes / 1e6);
    std::printf("  speed:        %.1f frames/s (rendering and writing, %d worker threads), %.2f s\n",
                s.frames_per_second, threads, s.seconds);
    std::printf(
        "  ground truth: %zu loop pairs + %zu negatives in pairs_distance.txt; %zu loop_distance4 rows (%zu reverse)\n",
        s.positives, s.negatives, s.loop_rows, s.reverse_loop_rows);
    std::printf("  peak memory:  %.0f MB\n", usage_info.ru_maxrss / 1024.0);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sglc-sim: error: " << e.what() << std::endl;
    return 1;
  }
}
