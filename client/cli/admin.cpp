// The map-administration subcommands of `sglc`: maps, robots, sessions, scan, stats, compact, delete, backup,
// create-map.
#include <iomanip>
#include <iostream>
#include <memory>

#include "common.hpp"
#include "sglc/client/packing.hpp"

namespace sglc::cli {
namespace {

json mapJson(const v1::MapInfo& m) {
  json j;
  j["name"] = m.name();
  j["scans"] = m.scans();
  j["robots"] = m.robots();
  j["sessions"] = m.sessions();
  j["descriptor_dim"] = m.descriptor_dim();
  return j;
}

int runMaps(const Common& common) {
  const auto maps = connectClient(common).listMaps();
  if (common.json) {
    json j;
    j["maps"] = json::array();
    for (const auto& m : maps) j["maps"].push_back(mapJson(m));
    std::cout << j.dump() << std::endl;
    return 0;
  }
  if (maps.empty()) {
    std::cout << "no maps\n";
    return 0;
  }
  std::cout << std::left << std::setw(24) << "MAP" << std::right << std::setw(10) << "SCANS" << std::setw(8) << "ROBOTS"
            << std::setw(10) << "SESSIONS"
            << "\n";
  for (const auto& m : maps)
    std::cout << std::left << std::setw(24) << m.name() << std::right << std::setw(10) << m.scans() << std::setw(8)
              << m.robots() << std::setw(10) << m.sessions() << "\n";
  return 0;
}

int runRobots(const Common& common, const std::string& map) {
  const auto robots = connectClient(common).listRobots(map);
  if (common.json) {
    json j;
    j["map"] = map;
    j["robots"] = json::array();
    for (const auto& r : robots)
      j["robots"].push_back({{"name", r.name()}, {"scans", r.scans()}, {"sessions", r.sessions()}});
    std::cout << j.dump() << std::endl;
    return 0;
  }
  if (robots.empty()) {
    std::cout << "no robots in map " << map << "\n";
    return 0;
  }
  std::cout << std::left << std::setw(24) << "ROBOT" << std::right << std::setw(10) << "SCANS" << std::setw(10)
            << "SESSIONS"
            << "\n";
  for (const auto& r : robots)
    std::cout << std::left << std::setw(24) << r.name() << std::right << std::setw(10) << r.scans() << std::setw(10)
              << r.sessions() << "\n";
  return 0;
}

int runSessions(const Common& common, const std::string& map, const std::string& robot) {
  const auto sessions = connectClient(common).listSessions(map, robot);
  if (common.json) {
    json j;
    j["map"] = map;
    j["sessions"] = json::array();
    for (const auto& s : sessions)
      j["sessions"].push_back({{"robot", s.robot()},
                               {"name", s.name()},
                               {"scans", s.scans()},
                               {"first_seq", s.first_seq()},
                               {"last_seq", s.last_seq()}});
    std::cout << j.dump() << std::endl;
    return 0;
  }
  if (sessions.empty()) {
    std::cout << "no sessions\n";
    return 0;
  }
  std::cout << std::left << std::setw(20) << "ROBOT" << std::setw(20) << "SESSION" << std::right << std::setw(10)
            << "SCANS" << std::setw(12) << "SEQ"
            << "\n";
  for (const auto& s : sessions)
    std::cout << std::left << std::setw(20) << s.robot() << std::setw(20) << s.name() << std::right << std::setw(10)
              << s.scans() << std::setw(12) << (std::to_string(s.first_seq()) + ".." + std::to_string(s.last_seq()))
              << "\n";
  return 0;
}

int runScan(const Common& common, std::int64_t id, bool graph) {
  const auto r = connectClient(common).getScan(id, graph);
  if (common.json) {
    json j;
    j["scan_id"] = r.scan_id();
    j["map"] = r.key().map();
    j["robot"] = r.key().robot();
    j["session"] = r.key().session();
    j["seq"] = r.key().seq();
    j["stamp"] = r.has_stamp() ? json(r.stamp()) : json(nullptr);
    j["odometry_pose"] = sc::isSet(r.odometry_pose()) ? transformJson(r.odometry_pose()) : json(nullptr);
    j["fingerprint_bytes"] = r.fingerprint_bytes();
    j["has_raw"] = r.has_raw();
    if (graph) {
      j["nodes"] = json::array();
      for (const auto& n : r.nodes())
        j["nodes"].push_back({{"cls", n.cls()},
                              {"x", n.x()},
                              {"y", n.y()},
                              {"z", n.z()},
                              {"length", n.length()},
                              {"width", n.width()},
                              {"height", n.height()}});
      j["scan_descriptor"] = std::vector<float>(r.scan_descriptor().begin(), r.scan_descriptor().end());
    }
    std::cout << j.dump() << std::endl;
    return 0;
  }
  std::cout << "scan " << r.scan_id() << ": map " << r.key().map() << ", robot " << r.key().robot() << ", session "
            << r.key().session() << ", seq " << r.key().seq() << "\n";
  if (r.has_stamp()) std::cout << "  stamp " << std::fixed << std::setprecision(6) << r.stamp() << " s\n";
  if (sc::isSet(r.odometry_pose())) std::cout << "  odometry pose " << poseText(r.odometry_pose()) << "\n";
  std::cout << "  fingerprint " << r.fingerprint_bytes() << " bytes" << (r.has_raw() ? ", raw cloud stored" : "")
            << "\n";
  if (graph) {
    std::cout << "  " << r.nodes_size() << " graph nodes\n";
    for (const auto& n : r.nodes())
      std::cout << "    " << std::left << std::setw(14) << n.cls() << std::right << std::fixed << std::setprecision(2)
                << " at (" << n.x() << ", " << n.y() << ", " << n.z() << ")  " << n.length() << " x " << n.width()
                << " x " << n.height() << " m\n";
  }
  return 0;
}

int runStats(const Common& common, const std::string& map) {
  const auto s = connectClient(common).getStats(map);
  if (common.json) {
    json j;
    if (!map.empty()) j["map"] = map;
    j["maps"] = s.maps();
    j["robots"] = s.robots();
    j["sessions"] = s.sessions();
    j["scans"] = s.scans();
    j["index_entries"] = s.index_entries();
    j["db_bytes"] = s.db_bytes();
    j["fingerprint_bytes"] = s.fingerprint_bytes();
    j["cache_mb"] = s.cache_mb();
    j["places"] = s.places();
    j["versions"] = s.versions();
    j["retired_scans"] = s.retired_scans();
    j["retired_bytes"] = s.retired_bytes();
    std::cout << j.dump() << std::endl;
    return 0;
  }
  std::cout << (map.empty() ? std::string("database") : "map " + map) << ":\n"
            << "  maps        " << s.maps() << "\n"
            << "  robots      " << s.robots() << "\n"
            << "  sessions    " << s.sessions() << "\n"
            << "  scans       " << s.scans() << "\n"
            << "  index       " << s.index_entries() << " entries\n"
            << "  database    " << std::fixed << std::setprecision(1) << s.db_bytes() / 1e6 << " MB\n"
            << "  fingerprints " << s.fingerprint_bytes() / 1e6 << " MB\n"
            << "  cache       " << s.cache_mb() << " MB\n";
  if (s.places() > 0 || s.retired_scans() > 0)
    std::cout << "  places      " << s.places() << " (" << s.versions() << " versions kept)\n"
              << "  retired     " << s.retired_scans() << " scans, " << s.retired_bytes() / 1e6 << " MB saved\n";
  return 0;
}

int runCompact(const Common& common, const std::string& map) {
  const auto r = connectClient(common).compact(map);
  if (common.json) {
    json j;
    j["map"] = map;
    j["policy_on"] = r.policy_on();
    j["placed"] = r.placed();
    j["promoted"] = r.promoted();
    j["demoted"] = r.demoted();
    j["retired"] = r.retired();
    j["retired_bytes"] = r.retired_bytes();
    j["loops_moved"] = r.loops_moved();
    j["loops_dropped"] = r.loops_dropped();
    j["open_sessions"] = r.open_sessions();
    j["places"] = r.places();
    j["versions"] = r.versions();
    std::cout << j.dump() << std::endl;
    return 0;
  }
  std::cout << "map " << map << (r.policy_on() ? "" : " (policy off: map.max_versions_per_place is 0)") << ":\n"
            << "  placed      " << r.placed() << " scans; " << r.promoted() << " surplus made versions, " << r.demoted()
            << " versions made surplus\n"
            << "  retired     " << r.retired() << " scans, " << std::fixed << std::setprecision(1)
            << r.retired_bytes() / 1e6 << " MB\n"
            << "  loops       " << r.loops_moved() << " moved to scans that stay, " << r.loops_dropped() << " dropped\n"
            << "  sessions    " << r.open_sessions() << " still within their retention, left whole\n"
            << "  places      " << r.places() << " (" << r.versions() << " versions kept)\n";
  return 0;
}

int runDelete(const Common& common, const std::string& map, const std::string& robot, const std::string& session) {
  const sc::Client client = connectClient(common);
  const std::int64_t removed =
      session.empty() ? client.deleteRobot(map, robot) : client.deleteSession(map, robot, session);
  if (common.json) {
    json j;
    j["map"] = map;
    j["robot"] = robot;
    if (!session.empty()) j["session"] = session;
    j["scans_removed"] = removed;
    std::cout << j.dump() << std::endl;
  } else {
    std::cout << "removed " << removed << " scans of robot " << robot << (session.empty() ? "" : ", session " + session)
              << " from map " << map << "\n";
  }
  return 0;
}

int runBackup(const Common& common, const std::string& path) {
  const auto r = connectClient(common).backup(path);
  if (common.json) {
    json j;
    j["path"] = r.path();
    j["bytes"] = r.bytes();
    std::cout << j.dump() << std::endl;
  } else {
    std::cout << "backup written to " << r.path() << " on the server (" << r.bytes() << " bytes)\n";
  }
  return 0;
}

// Without --yes nothing is deleted: the map's size is shown and the command fails.
int runDeleteMap(const Common& common, const std::string& map, bool yes) {
  const sc::Client client = connectClient(common);
  if (!yes) {
    const auto s = client.getStats(map);  // NOT_FOUND for an unknown map
    std::cerr << "sglc: error: map '" << map << "' holds " << s.scans() << " scans of " << s.robots()
              << " robots; deleting it cannot be undone: repeat with --yes\n";
    return 1;
  }
  const std::int64_t removed = client.deleteMap(map);
  if (common.json)
    std::cout << json{{"map", map}, {"deleted", true}, {"scans_removed", removed}}.dump() << std::endl;
  else
    std::cout << "deleted map " << map << " (" << removed << " scans)\n";
  return 0;
}

int runCreateMap(const Common& common, const std::string& name) {
  const auto m = connectClient(common).createMap(name);
  if (common.json) {
    std::cout << mapJson(m).dump() << std::endl;
  } else {
    std::cout << "created map " << m.name() << "\n";
  }
  return 0;
}

void addMapEdits(CLI::App& app, Common& common, Commands& out) {
  struct Del {
    std::string map, robot, session;
  };
  auto del = std::make_shared<Del>();
  auto* c = app.add_subcommand("delete", "Delete a robot's scans, or one of its sessions");
  addCommon(c, common);
  c->add_option("--map", del->map, "Map name")->required();
  c->add_option("--robot", del->robot, "Robot name")->required();
  c->add_option("--session", del->session, "Only this session");
  out.push_back({c, [&common, del] { return runDelete(common, del->map, del->robot, del->session); }});

  auto delete_map = std::make_shared<std::pair<std::string, bool>>();
  c = app.add_subcommand("delete-map", "Delete a whole map: scans, robots, sessions, loops, poses (irreversible)");
  addCommon(c, common);
  c->add_option("MAP", delete_map->first, "Map name")->required();
  c->add_flag("--yes", delete_map->second, "Really delete (without it: show the map's size and stop)");
  out.push_back({c, [&common, delete_map] { return runDeleteMap(common, delete_map->first, delete_map->second); }});

  auto backup_path = std::make_shared<std::string>();
  c = app.add_subcommand("backup", "Online backup of the database to a new file on the server");
  addCommon(c, common);
  c->add_option("NAME", *backup_path,
                "File name (no directories) the server writes into its backup directory (server.backup_dir; "
                "default backups/ beside the database); must not exist")
      ->required();
  out.push_back({c, [&common, backup_path] { return runBackup(common, *backup_path); }});

  c = app.add_subcommand("health", "grpc.health.v1 check: exit 0 when the server is SERVING, 1 otherwise (probes)");
  addCommon(c, common);
  out.push_back({c, [&common] {
                   // A probe answers for now: no retries.
                   const bool ok = connectClient(common, sc::kDefaultChunkBytes, 1).serving();
                   if (common.json)
                     std::cout << json{{"server", common.server}, {"serving", ok}}.dump() << std::endl;
                   else
                     std::cout << common.server << (ok ? " SERVING" : " NOT_SERVING") << "\n";
                   return ok ? 0 : 1;
                 }});

  auto create_name = std::make_shared<std::string>();
  c = app.add_subcommand("create-map", "Create an empty map");
  addCommon(c, common);
  c->add_option("MAP", *create_name, "Map name")->required();
  out.push_back({c, [&common, create_name] { return runCreateMap(common, *create_name); }});
}

}  // namespace

void addAdmin(CLI::App& app, Common& common, Commands& out) {
  auto* c = app.add_subcommand("maps", "List maps");
  addCommon(c, common);
  out.push_back({c, [&common] { return runMaps(common); }});

  auto robots_map = std::make_shared<std::string>();
  c = app.add_subcommand("robots", "List a map's robots");
  addCommon(c, common);
  c->add_option("--map", *robots_map, "Map name")->required();
  out.push_back({c, [&common, robots_map] { return runRobots(common, *robots_map); }});

  auto sessions = std::make_shared<std::pair<std::string, std::string>>();
  c = app.add_subcommand("sessions", "List a map's sessions");
  addCommon(c, common);
  c->add_option("--map", sessions->first, "Map name")->required();
  c->add_option("--robot", sessions->second, "Only this robot's sessions");
  out.push_back({c, [&common, sessions] { return runSessions(common, sessions->first, sessions->second); }});

  auto scan = std::make_shared<std::pair<std::int64_t, bool>>(0, false);
  c = app.add_subcommand("scan", "Show a stored scan");
  addCommon(c, common);
  c->add_option("ID", scan->first, "Scan id")->required();
  c->add_flag("--graph", scan->second, "Include the semantic graph nodes and the scan descriptor");
  out.push_back({c, [&common, scan] { return runScan(common, scan->first, scan->second); }});

  auto stats_map = std::make_shared<std::string>();
  c = app.add_subcommand("stats", "Database or map statistics");
  addCommon(c, common);
  c->add_option("--map", *stats_map, "Only this map");
  out.push_back({c, [&common, stats_map] { return runStats(common, *stats_map); }});

  auto compact_map = std::make_shared<std::string>();
  c = app.add_subcommand("compact",
                         "Apply the map's lifelong policy now: places, then retire what ended sessions "
                         "added beyond each place's versions (docs/LIFELONG.md)");
  addCommon(c, common);
  c->add_option("--map", *compact_map, "Map name")->required();
  out.push_back({c, [&common, compact_map] { return runCompact(common, *compact_map); }});
  addMapEdits(app, common, out);
}

}  // namespace sglc::cli
