// `sglc trajectory` and `sglc loops`: a map's pose graph out of the server, in the formats other tools read.
//
// trajectory --format kitti: 12 numbers per line (row-major 3x4), plus OUT.frames naming each line's robot,
//   session, frame number (seq) and scan id, so a subset (--every) still lines up with the ground truth.
// trajectory --format tum: "stamp tx ty tz qx qy qz qw" per line (evo, TUM RGB-D); needs stamps.
// loops --format json: one object per line; csv: a header and one row per loop; g2o: VERTEX_SE3:QUAT for every
//   scan at the end of a loop (at its optimised pose) and EDGE_SE3:QUAT per loop, information in g2o's order.
#include <fstream>
#include <iostream>
#include <memory>
#include <set>

#include "common.hpp"
#include "sglc/client/export_formats.hpp"
#include "sglc/client/packing.hpp"
#include "sglc/io.hpp"
#include "sglc/wire/geometry_codec.hpp"

namespace sglc::cli {
namespace {

std::ofstream openOut(const std::string& path) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) throw sglc::InputError(path + ": cannot write");
  return out;
}

void closeOut(std::ofstream& out, const std::string& path) {
  if (!out.flush()) throw sglc::InputError(path + ": write failed");
}

void writeKitti(const std::vector<v1::ScanPose>& poses, const std::string& path) {
  std::vector<Mat4d> matrices;
  auto frames = openOut(path + ".frames");
  frames << "# robot session seq scan_id, one line per pose of " << path << "\n";
  for (const auto& p : poses) {
    matrices.push_back(sglc::wire::toMatrix(p.t_map_scan()));
    frames << p.robot() << " " << p.session() << " " << p.seq() << " " << p.scan_id() << "\n";
  }
  sglc::writePoses(path, matrices);
  closeOut(frames, path + ".frames");
}

void writeTum(const std::vector<v1::ScanPose>& poses, const std::string& path) {
  std::vector<sglc::StampedPose> stamped;
  for (const auto& p : poses) {
    if (!p.has_stamp())
      throw sglc::InputError("scan " + std::to_string(p.scan_id()) + " (seq " + std::to_string(p.seq()) +
                             ") has no stamp: TUM needs times (ingest with times.txt or TUM poses), or use "
                             "--format kitti");
    stamped.push_back({p.stamp(), sglc::wire::toMatrix(p.t_map_scan())});
  }
  sglc::writeTumPoses(path, stamped);
}

struct TrajectoryArgs {
  std::string map, robot, session, out, format = "kitti";
};

int runTrajectory(const Common& common, const TrajectoryArgs& a) {
  if (a.format != "kitti" && a.format != "tum") throw UsageError("--format must be kitti or tum");
  const auto poses = connectClient(common).getPoses(a.map, a.robot, a.session);
  if (poses.empty())
    throw sglc::InputError("robot '" + a.robot + "' of map '" + a.map + "' has no scan with an odometry pose");
  a.format == "tum" ? writeTum(poses, a.out) : writeKitti(poses, a.out);
  std::int64_t optimised = 0, connected = 0;
  for (const auto& p : poses) {
    optimised += p.optimised();
    connected += p.connected();
  }
  if (common.json) {
    std::cout << json{{"map", a.map},           {"robot", a.robot},   {"poses", poses.size()}, {"optimised", optimised},
                      {"connected", connected}, {"format", a.format}, {"out", a.out}}
                     .dump()
              << std::endl;
  } else {
    std::cout << poses.size() << " poses of " << a.robot << " (" << optimised << " optimised, " << connected
              << " in the map frame) -> " << a.out << (a.format == "kitti" ? " (+ .frames)" : " (TUM)") << "\n";
  }
  return 0;
}

struct LoopsArgs {
  std::string map, robot, out, format = "json";
};

int runLoops(const Common& common, const LoopsArgs& a) {
  if (a.format != "json" && a.format != "csv" && a.format != "g2o")
    throw UsageError("--format must be json, csv or g2o");
  const sc::Client client = connectClient(common);
  const auto loops = client.getLoops(a.map, a.robot);
  std::ofstream file;
  if (!a.out.empty()) file = openOut(a.out);
  std::ostream& out = a.out.empty() ? std::cout : file;
  if (a.format == "json") {
    for (const auto& l : loops) out << sc::loopJson(l).dump() << "\n";
  } else if (a.format == "csv") {
    sc::writeLoopsCsv(loops, out);
  } else {
    std::set<std::int64_t> ends;
    for (const auto& l : loops) ends.insert({l.query().scan_id(), l.candidate().scan_id()});
    std::vector<v1::ScanPose> vertices;
    for (auto& p : client.getPoses(a.map))
      if (ends.count(p.scan_id())) vertices.push_back(std::move(p));
    if (const auto missing = sc::writeLoopsG2o(loops, vertices, out); missing > 0)
      std::cerr << "sglc: warning: " << missing
                << " loop ends have no pose (scans ingested without an odometry pose); written at the identity\n";
  }
  if (!a.out.empty()) {
    closeOut(file, a.out);
    std::cerr << loops.size() << " loops of map " << a.map << " -> " << a.out << "\n";
  }
  return 0;
}

}  // namespace

void addTrajectory(CLI::App& app, Common& common, Commands& out) {
  auto t = std::make_shared<TrajectoryArgs>();
  auto* c = app.add_subcommand("trajectory", "Write a robot's optimised poses (KITTI with a .frames list, or TUM)");
  addCommon(c, common);
  c->add_option("--map", t->map, "Map")->required();
  c->add_option("--robot", t->robot, "Robot")->required();
  c->add_option("--session", t->session, "Only this session");
  c->add_option("--format", t->format, "kitti (3x4 per line, + OUT.frames) or tum (stamp tx ty tz qx qy qz qw)")
      ->capture_default_str();
  c->add_option("--out", t->out, "Output file (map frame)")->required();
  out.push_back({c, [&common, t] { return runTrajectory(common, *t); }});

  auto l = std::make_shared<LoopsArgs>();
  c = app.add_subcommand("loops", "List the verified loops of a map's pose graph (json, csv or g2o)");
  addCommon(c, common);
  c->add_option("--map", l->map, "Map")->required();
  c->add_option("--robot", l->robot, "Only loops with an end in this robot's scans");
  c->add_option("--format", l->format,
                "json (one object per line), csv, or g2o (VERTEX_SE3:QUAT at optimised poses, EDGE_SE3:QUAT per loop)")
      ->capture_default_str();
  c->add_option("--out", l->out, "Output file (default: standard output)");
  out.push_back({c, [&common, l] { return runLoops(common, *l); }});
}

}  // namespace sglc::cli
