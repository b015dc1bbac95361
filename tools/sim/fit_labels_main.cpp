// sglc-sim-fit-labels: calibrates the network label noise preset. Renders HDL-64 frames of the built-in route
// (and of a KITTI trajectory when --poses/--calib are given) without label noise, fits one error strength per
// class so that the per-class IoU of noisy vs true labels matches RangeNet53++'s table (kRangeNetIou), and
// prints the strengths as the C++ line to freeze in NetworkNoiseParams::rangeNet(), with the IoU reached.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>

#include "sglc/frame_selection.hpp"
#include "sglc/version.hpp"
#include "sim/label_noise_network.hpp"

namespace {

struct Options {
  std::string poses_path, calib_path;
  std::string loop_frames = "0:1911:80", kitti_frames = "0:4541:190";
  std::uint64_t seed = 7;
  int iterations = 30, threads = 2;
};

void render(const sglc::sim::Trajectory& traj, const std::string& spec, const Options& o,
            std::vector<sglc::sim::Frame>& out) {
  sglc::sim::SimConfig cfg;
  cfg.seed = o.seed;
  const sglc::sim::Simulator sim(traj, cfg);
  for (int f : sglc::FrameSelection::parse(spec).frames(sim.numFrames())) {
    out.emplace_back();
    sim.render(f, out.back(), o.threads);
  }
  std::cerr << "sglc-sim-fit-labels: rendered " << spec << " of " << traj.source << std::endl;
}

void printTable(const sglc::sim::LabelIouCounts& counts) {
  using namespace sglc::sim;
  std::printf("| class | RangeNet53++ | fitted | difference | true points |\n|---|---|---|---|---|\n");
  for (int k = 0; k < kEvalClasses; ++k) {
    if (!counts.present(k)) {
      std::printf("| %s | %.1f | - | - | 0 |\n", kEvalClassTable[k].name, kRangeNetIou[k]);
      continue;
    }
    std::printf("| %s | %.1f | %.1f | %+.1f | %llu |\n", kEvalClassTable[k].name, kRangeNetIou[k],
                100.0 * counts.iou(k), 100.0 * counts.iou(k) - kRangeNetIou[k],
                static_cast<unsigned long long>(counts.truthPoints(k)));
  }
  std::printf("mIoU over the classes present: %.1f\n", 100.0 * counts.meanIou());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Fits the per-class strengths of sglc-sim's network label noise preset to RangeNet53++'s IoU table"};
  app.set_version_flag("--version", std::string("sglc-sim-fit-labels ") + sglc::kVersion);
  Options o;
  app.add_option("--poses", o.poses_path, "KITTI poses file to render frames of as well (with --calib)");
  app.add_option("--calib", o.calib_path, "calib.txt whose Tr converts --poses");
  app.add_option("--loop-frames", o.loop_frames, "Frames of the built-in route")->capture_default_str();
  app.add_option("--kitti-frames", o.kitti_frames, "Frames of --poses")->capture_default_str();
  app.add_option("--seed", o.seed, "World and noise seed")->capture_default_str();
  app.add_option("--iterations", o.iterations, "Fit rounds")->capture_default_str()->check(CLI::Range(1, 1000));
  app.add_option("--threads", o.threads, "Threads per rendered frame")->capture_default_str()->check(CLI::Range(1, 64));
  CLI11_PARSE(app, argc, argv);
  if (o.poses_path.empty() != o.calib_path.empty()) {
    std::cerr << "sglc-sim-fit-labels: error: --poses and --calib go together" << std::endl;
    return 2;
  }
  try {
    using namespace sglc::sim;
    std::vector<Frame> frames;
    render(loopRoute(), o.loop_frames, o, frames);
    if (!o.poses_path.empty()) render(loadKittiTrajectory(o.poses_path, o.calib_path), o.kitti_frames, o, frames);
    const SensorConfig sensor = SensorConfig::hdl64();
    NetworkNoiseParams start = NetworkNoiseParams::rangeNet();
    const NetworkNoiseParams fitted =
        fitNetworkNoise(frames, start, o.seed, sensor.beams(), sensor.columns, o.iterations,
                        [](const std::string& line) { std::cerr << "sglc-sim-fit-labels: " << line << std::endl; });
    printTable(evaluateNetworkNoise(frames, fitted, o.seed, sensor.beams(), sensor.columns));
    std::printf("  p.strength = {");
    for (int k = 0; k < kEvalClasses; ++k) std::printf("%s%.4g", k ? ", " : "", fitted.strength[k]);
    std::printf("};\n");
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sglc-sim-fit-labels: error: " << e.what() << std::endl;
    return 1;
  }
}
