// The SLAM protocol: robots with drifting odometry feed a running server, whose pose graph corrects them;
// scored by absolute trajectory error before and after, and by how well the second robot's frame is found.
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>

#include "progress.hpp"
#include "protocols.hpp"
#include "sglc/client/client.hpp"
#include "sim/ground_truth.hpp"

namespace sglc::eval {
namespace {

struct Robot {
  std::string name;
  std::vector<int> frames;
  std::vector<Mat4d> gt, odom;
};

// One robot driving frames [first, last) with odometry that drifts as sglc-sim --odom-noise and starts at
// `frame`.
Robot makeRobot(const Run& run, const SlamOptions& o, const std::string& name, std::size_t first, std::size_t last,
                const Mat4d& frame, std::uint64_t index) {
  const auto& frames = run.source.frames();
  Robot r{name, {}, {}, {}};
  for (auto k = first; k < last; ++k) {
    r.frames.push_back(frames[k]);
    r.gt.push_back(run.source.pose(frames[k]));
  }
  const sim::OdometryNoise noise{o.odom_noise, 0.5 * o.odom_noise};
  const auto drift = sim::driftingOdometry(r.gt, r.frames, noise, o.seed + index);
  const Mat4d to_frame = frame * drift.front().inverse();
  for (const auto& T : drift) r.odom.push_back(to_frame * T);
  return r;
}

std::vector<Robot> makeRobots(const Run& run, const SlamOptions& o) {
  const auto& frames = run.source.frames();
  for (int f : frames)
    if (!run.source.hasPose(f)) throw InputError("frame " + std::to_string(f) + " has no ground-truth pose");
  const std::size_t n = frames.size();
  const Mat4d world = run.source.pose(frames.front());
  if (o.robots == 1) return {makeRobot(run, o, "r0", 0, n, world, 0)};
  Mat4d unrelated = Mat4d::Identity();
  unrelated.block<3, 3>(0, 0) = Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  unrelated.block<3, 1>(0, 3) = Eigen::Vector3d(50, -20, 3);
  return {makeRobot(run, o, "r0", 0, n * 6 / 10, world, 0), makeRobot(run, o, "r1", n * 4 / 10, n, unrelated, 1)};
}

StageTimes stageTimes(const v1::IngestResponse& resp) {
  StageTimes t;
  t.fingerprint = resp.timing().fingerprint_ms();
  t.search = resp.timing().search_ms();
  t.verify = resp.timing().verify_ms();
  t.refine = resp.timing().refine_ms();
  t.store = resp.timing().store_ms();
  t.total = resp.timing().total_ms();
  return t;
}

// Ingests every robot's frames with loop queries; returns the verified loops the server reported.
std::size_t ingestAll(Run& run, const client::Client& cl, const SlamOptions& o, const std::vector<Robot>& robots,
                      std::size_t total) {
  std::size_t loops = 0, done = 0;
  Progress bar("ingest", total);
  for (const auto& r : robots) {
    Prefetch pre(run.source, r.frames, run.threads);
    for (std::size_t k = 0; k < r.frames.size(); ++k) {
      auto [f, scan] = pre.next();
      client::IngestOptions io;
      io.odometry_pose = r.odom[k];
      io.query = true;
      io.query_options.set_exclude_recent(o.exclude_recent);
      io.query_options.set_top_k(3);
      const auto resp = cl.ingest(client::makeKey(o.map, r.name, "run", f), scan, io);
      for (const auto& c : resp.loops()) loops += c.verified();
      run.timings.add(stageTimes(resp));
      bar.step(++done);
    }
  }
  return loops;
}

// The map's first converged pose-graph event covering at least `nodes` scans and `loops` loops, or the last
// event seen when `timeout` passes first (converged() false then).
v1::MapEvent waitForSettledGraph(const client::Client& cl, const std::string& map, std::int64_t nodes,
                                 std::int64_t loops, std::chrono::seconds timeout) {
  auto stub = v1::PoseGraph::NewStub(cl.channel());
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + timeout);
  v1::WatchMapRequest req;
  req.set_map(map);
  auto reader = stub->WatchMap(&ctx, req);
  v1::MapEvent last, e;
  while (reader->Read(&e)) {
    last = e;
    if (e.converged() && !e.failed() && e.nodes() >= nodes && e.loops() >= loops) {
      ctx.TryCancel();
      break;
    }
  }
  reader->Finish();  // cancelled or deadline: the event decides
  if (last.failed() || !(last.converged() && last.nodes() >= nodes && last.loops() >= loops)) last.set_converged(false);
  return last;
}

// The server's optimised pose of each of the robot's frames.
std::vector<Mat4d> optimisedPoses(const client::Client& cl, const std::string& map, const Robot& r) {
  std::map<std::int64_t, Mat4d> opt;
  for (const auto& p : cl.getPoses(map, r.name)) opt[p.seq()] = client::toMatrix(p.t_map_scan());
  std::vector<Mat4d> est;
  for (int f : r.frames) {
    const auto it = opt.find(f);
    if (it == opt.end())
      throw std::runtime_error("the server has no pose for " + r.name + " frame " + std::to_string(f));
    est.push_back(it->second);
  }
  return est;
}

// ATE of the odometry (each robot aligned on its own, its best case) and of the optimised poses (all robots
// with one alignment, so a robot left in the wrong frame counts); slam.csv for the figure.
void scoreTrajectories(Run& run, const client::Client& cl, const std::string& map, const std::vector<Robot>& robots) {
  std::vector<Mat4d> all_opt, all_gt;
  double odom_sq = 0;
  std::ofstream csv(run.out + "/slam.csv");
  csv << "frame,robot,gt_x,gt_y,odom_x,odom_y,opt_x,opt_y\n" << std::setprecision(9);
  ordered_json per_robot = ordered_json::array();
  for (const auto& r : robots) {
    const auto est = optimisedPoses(cl, map, r);
    std::vector<Eigen::Vector3d> odom_aligned;
    const double ate_odom = absoluteTrajectoryError(r.odom, r.gt, &odom_aligned);
    odom_sq += ate_odom * ate_odom * static_cast<double>(r.frames.size());
    per_robot.push_back({{"robot", r.name},
                         {"frames", r.frames.size()},
                         {"ate_odometry", ate_odom},
                         {"ate_optimised", absoluteTrajectoryError(est, r.gt)}});
    for (std::size_t k = 0; k < r.frames.size(); ++k)
      csv << r.frames[k] << "," << r.name << "," << r.gt[k](0, 3) << "," << r.gt[k](1, 3) << "," << odom_aligned[k].x()
          << "," << odom_aligned[k].y() << "," << est[k](0, 3) << "," << est[k](1, 3) << "\n";
    all_opt.insert(all_opt.end(), est.begin(), est.end());
    all_gt.insert(all_gt.end(), r.gt.begin(), r.gt.end());
  }
  run.summary["ate_odometry"] = std::sqrt(odom_sq / static_cast<double>(all_gt.size()));
  run.summary["ate_optimised"] = absoluteTrajectoryError(all_opt, all_gt);
  run.summary["per_robot"] = per_robot;
}

// The map frame is r0's odometry frame, which starts at r0's true first pose (the world frame): r1's frame
// truly sits at gt(first) * inverse(odom(first)).
void scoreFrameAlignment(Run& run, const client::Client& cl, const std::string& map, const Robot& second) {
  const auto frames = cl.getSessionFrames(map);
  for (const auto& s : frames.sessions()) {
    if (s.robot() != second.name) continue;
    const Mat4d T = client::toMatrix(s.t_map_session());
    const Mat4d truth = second.gt.front() * second.odom.front().inverse();
    const auto e = poseError(T, truth);
    run.summary["frame_alignment_error"] = {{"m", e.rte_m}, {"deg", e.rre_deg}, {"connected", s.connected()}};
  }
}

}  // namespace

void slamProtocol(Run& run, const SlamOptions& o) {
  const auto robots = makeRobots(run, o);
  const auto cl = client::Client::connect(o.server, {.token = o.token, .default_deadline = std::chrono::minutes(5)});
  cl.createMap(o.map);
  std::size_t total = 0;
  for (const auto& r : robots) total += r.frames.size();
  const std::size_t loops = ingestAll(run, cl, o, robots, total);
  // The server optimises off the request path: wait for its converged solve of every scan and loop.
  const auto settled = waitForSettledGraph(cl, o.map, static_cast<std::int64_t>(total),
                                           static_cast<std::int64_t>(loops), std::chrono::minutes(5));
  if (!settled.converged())
    std::cerr << "warning: the pose graph did not settle within 5 minutes (last version " << settled.graph_version()
              << ", " << settled.nodes() << " nodes, " << settled.loops() << " loops)\n";
  run.summary["graph_converged"] = settled.converged();
  run.summary["loops_reported"] = loops;
  run.summary["graph_version"] = settled.graph_version();
  run.summary["odom_noise"] = o.odom_noise;
  run.summary["robots"] = o.robots;
  scoreTrajectories(run, cl, o.map, robots);
  if (robots.size() == 2) scoreFrameAlignment(run, cl, o.map, robots[1]);
  run.summary["server_map_kept"] = o.keep_map;
  if (!o.keep_map) cl.deleteMap(o.map);
}

}  // namespace sglc::eval
