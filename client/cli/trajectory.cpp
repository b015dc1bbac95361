// `sglc trajectory`: a robot's optimised poses from the server's pose graph, written to a file.
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>

#include "common.hpp"
#include "sglc/client/packing.hpp"

namespace sglc::cli {
namespace {

// KITTI-format poses (12 numbers per line, row-major 3x4) of a robot's optimised trajectory.
int runTrajectory(const Common& common, const std::string& map, const std::string& robot, const std::string& session,
                  const std::string& out_path) {
  const auto poses = connectClient(common).getPoses(map, robot, session);
  if (poses.empty())
    throw sglc::InputError("robot '" + robot + "' of map '" + map + "' has no scan with an odometry pose");
  std::ofstream out(out_path);
  if (!out) throw sglc::InputError(out_path + ": cannot write");
  out << std::setprecision(9);
  std::int64_t optimised = 0, connected = 0;
  for (const auto& p : poses) {
    for (int k = 0; k < 12; ++k) out << (k ? " " : "") << p.t_map_scan().m(k);
    out << "\n";
    optimised += p.optimised();
    connected += p.connected();
  }
  if (!out.flush()) throw sglc::InputError(out_path + ": write failed");
  if (common.json) {
    std::cout << json{{"map", map},
                      {"robot", robot},
                      {"poses", poses.size()},
                      {"optimised", optimised},
                      {"connected", connected},
                      {"out", out_path}}
                     .dump()
              << std::endl;
  } else {
    std::cout << poses.size() << " poses of " << robot << " (" << optimised << " optimised, " << connected
              << " in the map frame) -> " << out_path << "\n";
  }
  return 0;
}

}  // namespace

void addTrajectory(CLI::App& app, Common& common, Commands& out) {
  struct Args {
    std::string map, robot, session, out;
  };
  auto a = std::make_shared<Args>();
  auto* c = app.add_subcommand("trajectory", "Write a robot's optimised poses (KITTI format)");
  addCommon(c, common);
  c->add_option("--map", a->map, "Map")->required();
  c->add_option("--robot", a->robot, "Robot")->required();
  c->add_option("--session", a->session, "Only this session");
  c->add_option("--out", a->out, "Output file (one 3x4 row-major pose per line, map frame)")->required();
  out.push_back({c, [&common, a] { return runTrajectory(common, a->map, a->robot, a->session, a->out); }});
}

}  // namespace sglc::cli
