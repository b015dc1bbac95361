// sglc-bench-graph: time of the server's pose-graph optimisation per loop event on a map of several thousand
// scans, printed as one JSON object.
//
// The map: robot r0 drives KITTI 00's path (4541 frames when ../shared/data is present, else laps of the
// built-in route) with drifting odometry (1 %); robot r1 drives its start again, in an unrelated odometry frame,
// up to --scans scans in all. Loops: every pair of r0's frames less than 3 m and more than 100 frames apart
// (at most 3 per query frame, the nearest), and each r1 frame with the r0 frame it repeats, with the relative
// pose disturbed by 1 cm / 0.02 deg and an information matrix to match. All but the last --events query frames'
// loops are in the map first; one cold optimisation runs; then each remaining query frame's loops arrive as one
// event and the map is optimised again, warm-started, as the server's worker does.
//
//   build/bin/sglc-bench-graph [--scans 5000] [--events 50] [--dir /tmp/sglc-bench-graph]
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>

#include "sglc/descriptors.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"
#include "sim/ground_truth.hpp"
#include "sim/simulator.hpp"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using namespace sglc;

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5)];
}

// Positions' RMSE after the best rigid alignment.
double ate(const std::vector<Mat4d>& est, const std::vector<Mat4d>& gt) {
  Eigen::Matrix3Xd a(3, est.size()), b(3, gt.size());
  for (std::size_t i = 0; i < est.size(); ++i) {
    a.col(static_cast<Eigen::Index>(i)) = est[i].block<3, 1>(0, 3);
    b.col(static_cast<Eigen::Index>(i)) = gt[i].block<3, 1>(0, 3);
  }
  const Mat4d T = Eigen::umeyama(a, b, false);
  return std::sqrt(((T.block<3, 3>(0, 0) * a).colwise() + T.block<3, 1>(0, 3) - b).colwise().squaredNorm().mean());
}

// A valid fingerprint with a random scan descriptor: the pose graph needs scans, not their content.
Fingerprint placeholder(std::mt19937_64& rng) {
  Fingerprint fp;
  fp.layout = DescriptorLayout{};
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  fp.descriptor.resize(static_cast<std::size_t>(fp.layout.scanDim()));
  double norm = 0;
  for (auto& v : fp.descriptor) {
    v = u(rng);
    norm += double(v) * v;
  }
  for (auto& v : fp.descriptor) v = static_cast<float>(v / std::sqrt(norm));
  fp.instance_offsets.assign(1, 0);
  fp.finalize();
  return fp;
}

Mat4d disturbed(const Mat4d& T, std::mt19937_64& rng, double sigma_m, double sigma_rad) {
  std::normal_distribution<double> t(0.0, sigma_m), r(0.0, sigma_rad);
  const Eigen::Vector3d w(r(rng), r(rng), r(rng));
  Mat4d E = Mat4d::Identity();
  if (w.norm() > 0) E.block<3, 3>(0, 0) = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
  E.block<3, 1>(0, 3) = Eigen::Vector3d(t(rng), t(rng), t(rng));
  return T * E;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Pose-graph optimisation benchmark (JSON on stdout)."};
  std::string dir = (fs::temp_directory_path() / "sglc-bench-graph").string();
  std::string data = "../shared/data";
  int scans = 5000, events = 50;
  app.add_option("--dir", dir, "scratch directory (removed first)");
  app.add_option("--data", data, "shared data directory (KITTI poses)");
  app.add_option("--scans", scans, "scans in the map")->check(CLI::Range(200, 200000));
  app.add_option("--events", events, "loop events timed on the full map")->check(CLI::Range(1, 10000));
  CLI11_PARSE(app, argc, argv);
  // The optimiser logs each event; stdout carries only the JSON.
  spdlog::set_default_logger(spdlog::stderr_logger_st("bench"));

  fs::remove_all(dir);
  fs::create_directories(dir);
  sim::Trajectory traj;
  const auto poses = data + "/kitti_odometry_gt_poses/poses/00.txt";
  const auto calib = data + "/semantickitti_scans/sequences/00/calib.txt";
  if (fs::exists(poses) && fs::exists(calib))
    traj = sim::loadKittiTrajectory(poses, calib);
  else
    traj = sim::loopRoute();
  const int n0 = std::min(scans, static_cast<int>(traj.poses.size()));
  const int n1 = std::min(scans - n0, n0);  // r1 repeats r0's start

  // Ground truth and drifting odometry of both robots.
  std::vector<Mat4d> gt0(traj.poses.begin(), traj.poses.begin() + n0), gt1(traj.poses.begin(), traj.poses.begin() + n1);
  std::vector<int> src0(static_cast<std::size_t>(n0)), src1(static_cast<std::size_t>(n1));
  for (int i = 0; i < n0; ++i) src0[static_cast<std::size_t>(i)] = i;
  for (int i = 0; i < n1; ++i) src1[static_cast<std::size_t>(i)] = i;
  const sim::OdometryNoise noise{0.01, 0.005};
  const auto odom0 = sim::driftingOdometry(gt0, src0, noise, 11);
  auto odom1 = n1 > 0 ? sim::driftingOdometry(gt1, src1, noise, 12) : std::vector<Mat4d>{};
  Mat4d unrelated = Mat4d::Identity();
  unrelated.block<3, 3>(0, 0) = Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  unrelated.block<3, 1>(0, 3) = Eigen::Vector3d(50, -20, 3);
  for (auto& T : odom1) T = unrelated * T;

  storage::StoreOptions so;
  so.path = dir + "/graph.db";
  so.sync = storage::StoreOptions::Sync::kNormal;
  auto store = storage::MapStore::open(so);
  store->createMap("m", DescriptorLayout{}.scanDim());
  std::mt19937_64 rng(7);
  std::vector<std::int64_t> id0, id1;
  const auto t_fill = Clock::now();
  for (int i = 0; i < n0; ++i) {
    const auto fp = placeholder(rng);
    id0.push_back(store->addScan({.map = "m",
                                  .robot = "r0",
                                  .session = "s",
                                  .seq = i,
                                  .odometry_pose = odom0[static_cast<std::size_t>(i)],
                                  .fingerprint = &fp}));
  }
  for (int i = 0; i < n1; ++i) {
    const auto fp = placeholder(rng);
    id1.push_back(store->addScan({.map = "m",
                                  .robot = "r1",
                                  .session = "s",
                                  .seq = i,
                                  .odometry_pose = odom1[static_cast<std::size_t>(i)],
                                  .fingerprint = &fp}));
  }
  const double fill_s = std::chrono::duration<double>(Clock::now() - t_fill).count();

  // Loops grouped by the query frame that finds them, in the order they would arrive.
  const double sigma_m = 0.01, sigma_rad = 0.02 * 3.14159265358979 / 180.0;
  Mat6d info = Mat6d::Zero();
  info.diagonal() << 1 / (sigma_m * sigma_m), 1 / (sigma_m * sigma_m), 1 / (sigma_m * sigma_m),
      1 / (sigma_rad * sigma_rad), 1 / (sigma_rad * sigma_rad), 1 / (sigma_rad * sigma_rad);
  std::vector<std::vector<storage::LoopRecord>> groups;
  {
    std::map<int, std::vector<sim::LoopPose>> by_query;
    for (const auto& l : sim::loopPoses(gt0, src0, 3.0, 100)) by_query[l.second].push_back(l);
    for (auto& [q, ls] : by_query) {
      std::sort(ls.begin(), ls.end(), [](const sim::LoopPose& a, const sim::LoopPose& b) {
        return a.T.topRightCorner<3, 1>().norm() < b.T.topRightCorner<3, 1>().norm();
      });
      std::vector<storage::LoopRecord> g;
      for (std::size_t k = 0; k < std::min<std::size_t>(3, ls.size()); ++k) {
        // loopPoses' T maps `first` (earlier, the candidate) into `second` (the query).
        storage::LoopRecord r{0,
                              id0[static_cast<std::size_t>(q)],
                              id0[static_cast<std::size_t>(ls[k].first)],
                              disturbed(ls[k].T, rng, sigma_m, sigma_rad),
                              0.5,
                              0.9,
                              sigma_m,
                              20};
        r.information = info;
        g.push_back(r);
      }
      groups.push_back(std::move(g));
    }
    for (int i = 0; i < n1; ++i) {  // r1 frame i is where r0's frame i was
      storage::LoopRecord r{0,
                            id1[static_cast<std::size_t>(i)],
                            id0[static_cast<std::size_t>(i)],
                            disturbed(Mat4d::Identity(), rng, sigma_m, sigma_rad),
                            0.5,
                            0.9,
                            sigma_m,
                            20};
      r.information = info;
      groups.push_back({r});
    }
  }
  const int timed = std::min<int>(events, static_cast<int>(groups.size()) - 1);
  std::size_t loops = 0;
  for (std::size_t k = 0; k + static_cast<std::size_t>(timed) < groups.size(); ++k)
    for (const auto& r : groups[k]) loops += store->addLoop("m", r) > 0;

  posegraph::GraphOptimiserOptions o;
  o.max_seconds = 60;
  o.max_continuations = 0;  // each timed optimiseNow is the only solve of its loops
  // Its worker's start-up solve of the map may run first; optimiseNow then returns that solve's event.
  posegraph::GraphOptimiser graph(*store, o);
  const auto cold = graph.optimiseNow("m");
  std::vector<double> event_ms;
  for (std::size_t k = groups.size() - static_cast<std::size_t>(timed); k < groups.size(); ++k) {
    for (const auto& r : groups[k]) loops += store->addLoop("m", r) > 0;
    event_ms.push_back(graph.optimiseNow("m").optimise_ms);
  }
  graph.stop();

  // Sanity: the optimised trajectory against the truth.
  std::map<std::int64_t, Mat4d> opt;
  for (const auto& p : store->optimisedPoses("m", "", "", 0, std::numeric_limits<std::int64_t>::max()))
    opt[p.scan_id] = p.pose;
  std::vector<Mat4d> est, truth, odo;
  for (int i = 0; i < n0; ++i) {
    est.push_back(opt.at(id0[static_cast<std::size_t>(i)]));
    truth.push_back(gt0[static_cast<std::size_t>(i)]);
    odo.push_back(odom0[static_cast<std::size_t>(i)]);
  }
  nlohmann::ordered_json out;
  out["trajectory"] = traj.source;
  out["scans"] = n0 + n1;
  out["robots"] = n1 > 0 ? 2 : 1;
  out["loops"] = loops;
  out["fill_s"] = fill_s;
  out["cold_optimisation_ms"] = cold.optimise_ms;
  out["loop_event_ms"] = {{"median", percentile(event_ms, 0.5)},
                          {"p90", percentile(event_ms, 0.9)},
                          {"max", percentile(event_ms, 1.0)},
                          {"n", event_ms.size()}};
  out["ate_odometry_r0_m"] = ate(odo, truth);
  out["ate_optimised_r0_m"] = ate(est, truth);
  std::cout << out.dump(2) << std::endl;
  fs::remove_all(dir);
  return 0;
}
