// `sglc trajectory` and `sglc loops`: a map's pose graph out of the server, in the formats other tools read.
//
// trajectory --format kitti: 12 numbers per line (row-major 3x4), plus OUT.frames naming each line's robot,
//   session, frame number (seq) and scan id, so a subset (--every) still lines up with the ground truth.
// trajectory --format tum: "stamp tx ty tz qx qy qz qw" per line (evo, TUM RGB-D); needs stamps.
// loops --format json: one object per line; csv: a header and one row per loop.
// export --format g2o|json: the whole pose graph as the server weighs it (PoseGraph.ExportGraph) into a directory.
#include <filesystem>
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
  if (a.format == "g2o")
    throw UsageError("g2o is the whole pose graph now: sglc export --map " + a.map + " --format g2o --out DIR");
  if (a.format != "json" && a.format != "csv") throw UsageError("--format must be json or csv");
  const sc::Client client = connectClient(common);
  const auto loops = client.getLoops(a.map, a.robot);
  std::ofstream file;
  if (!a.out.empty()) file = openOut(a.out);
  std::ostream& out = a.out.empty() ? std::cout : file;
  if (a.format == "json") {
    for (const auto& l : loops) out << sc::loopJson(l).dump() << "\n";
  } else {
    sc::writeLoopsCsv(loops, out);
  }
  if (!a.out.empty()) {
    closeOut(file, a.out);
    std::cerr << loops.size() << " loops of map " << a.map << " -> " << a.out << "\n";
  }
  return 0;
}

struct ExportArgs {
  std::string map, out, format = "g2o";
  std::vector<std::string> robots;
};

// A file name the server sent: a plain name, never a path.
void checkFileName(const std::string& name) {
  const bool plain = !name.empty() && name.size() <= 64 &&
                     name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-") ==
                         std::string::npos &&
                     name[0] != '.';
  if (!plain) throw sglc::InputError("the server sent an export file named '" + name.substr(0, 64) + "': refused");
}

int runExport(const Common& common, const ExportArgs& a) {
  if (a.format != "g2o" && a.format != "json" && a.format != "mcap")
    throw UsageError("--format must be g2o, json or mcap");
  const sc::Client client = connectClient(common);
  v1::ExportGraphRequest request;
  request.set_map(a.map);
  request.set_format(a.format);
  for (const auto& r : a.robots) request.add_robots(r);
  v1::ExportSummary summary;
  const auto files = client.exportGraph(request, &summary);
  std::error_code ec;
  std::filesystem::create_directories(a.out, ec);
  if (ec) throw sglc::InputError(a.out + ": cannot create the directory: " + ec.message());
  for (const auto& f : files) {
    checkFileName(f.name);
    const auto path = (std::filesystem::path(a.out) / f.name).string();
    auto out = openOut(path);
    out << f.data;
    closeOut(out, path);
  }
  std::cerr << "map " << a.map << " (graph version " << summary.graph_version() << "): " << summary.nodes()
            << " scans, " << summary.odometry_edges() << " odometry edges, " << summary.loop_edges() << " loops -> "
            << a.out << "\n";
  if (a.format == "mcap" && summary.keyframes() == 0 && summary.nodes() > 0)
    std::cerr << "sglc: note: no keyframe points in graph.mcap: the server keeps a scan's points only when it "
                 "was ingested with --store-raw\n";
  else if (a.format == "mcap")
    std::cerr << summary.keyframes() << " keyframes' points in graph.mcap\n";
  if (summary.loops_left_out() > 0)
    std::cerr << "sglc: warning: " << summary.loops_left_out()
              << " verified loops cannot join the graph (an end without odometry pose, or another robot's); listed in "
              << (a.format == "g2o"    ? "graph.left_out.csv"
                  : a.format == "json" ? "the JSON's left_out"
                                       : "--format json")
              << "\n";
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
  c = app.add_subcommand("loops", "List the verified loops of a map's pose graph (json or csv)");
  addCommon(c, common);
  c->add_option("--map", l->map, "Map")->required();
  c->add_option("--robot", l->robot, "Only loops with an end in this robot's scans");
  c->add_option("--format", l->format, "json (one object per line) or csv")->capture_default_str();
  c->add_option("--out", l->out, "Output file (default: standard output)");
  out.push_back({c, [&common, l] { return runLoops(common, *l); }});

  auto e = std::make_shared<ExportArgs>();
  c = app.add_subcommand(
      "export",
      "Write a map's whole pose graph, as the server weighs it, for another back-end (g2o, json) or Foxglove (mcap)");
  addCommon(c, common);
  c->add_option("--map", e->map, "Map")->required();
  c->add_option("--robot", e->robots, "Only these robots' scans (repeatable; default: every robot)");
  c->add_option("--format", e->format,
                "g2o (graph.g2o, graph.ids.csv naming each vertex, graph.left_out.csv), json (graph.json) or mcap "
                "(graph.mcap, for Foxglove)")
      ->capture_default_str();
  c->add_option("--out", e->out, "Output directory (created)")->required();
  out.push_back({c, [&common, e] { return runExport(common, *e); }});
}

}  // namespace sglc::cli
