// sglc: command line client of the SGLC loop-closure service. See client/README.md.
//
// Exit status: 0 success, 1 failure (bad input, server error), 2 bad command line. Every failure prints
// exactly one line "sglc: error: ..." on stderr; server errors name the gRPC status (e.g. NOT_FOUND).
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "sglc/client/client.hpp"
#include "sglc/client/packing.hpp"
#include "sglc/io.hpp"
#include "sglc/sequence.hpp"

namespace {

using json = nlohmann::ordered_json;
namespace sc = sglc::client;
namespace v1 = sglc::v1;

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::string oneLine(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  std::replace(s.begin(), s.end(), '\r', ' ');
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

// ---------------------------------------------------------------------------------------------------------
// Options shared by every subcommand

struct Common {
  std::string server = "127.0.0.1:50051";
  std::string token;
  std::string tls_ca;
  double timeout_s = 30;
  bool json = false;
};

void addCommon(CLI::App* app, Common& c) {
  app->add_option("--server", c.server, "Server address host:port (default 127.0.0.1:50051, or $SGLC_SERVER)");
  app->add_option("--token", c.token, "Bearer token (default $SGLC_TOKEN)");
  app->add_option("--tls-ca", c.tls_ca, "PEM file of root certificates: use TLS and verify the server with them");
  app->add_option("--timeout", c.timeout_s, "Deadline of each call in seconds (default 30; 0: none)");
  app->add_flag("--json", c.json, "Machine-readable output (JSON)");
}

sc::Client connectClient(const Common& c, std::size_t chunk_bytes = sc::kDefaultChunkBytes) {
  sc::ConnectOptions options;
  options.chunk_bytes = chunk_bytes;
  options.token = c.token;
  if (!c.tls_ca.empty()) {
    std::ifstream in(c.tls_ca, std::ios::binary);
    if (!in) throw sglc::InputError("--tls-ca " + c.tls_ca + ": cannot read");
    std::ostringstream ss;
    ss << in.rdbuf();
    options.tls_root_certs = ss.str();
    if (options.tls_root_certs.find("-----BEGIN") == std::string::npos)
      throw sglc::InputError("--tls-ca " + c.tls_ca + ": not a PEM certificate file");
  }
  if (!(c.timeout_s >= 0) || !std::isfinite(c.timeout_s))
    throw UsageError("--timeout must be a number of seconds >= 0");
  options.default_deadline = std::chrono::milliseconds(static_cast<std::int64_t>(c.timeout_s * 1000.0));
  if (c.server.empty()) throw UsageError("--server is empty");
  return sc::Client::connect(c.server, options);
}

// ---------------------------------------------------------------------------------------------------------
// Query options (ingest --query and query)

struct QueryFlags {
  unsigned top_k = 0;  // 0: the server's default (5)
  std::int64_t exclude_recent = 50;
  double exclude_seconds = 0;
  std::string scope = "all";
  std::string sessions;  // comma separated robot/session names
  unsigned candidates = 0;
  bool no_refine = false;
  bool include_rejected = false;
  bool known_loops = false;
  std::vector<std::int64_t> verify_scan_ids;
  double min_score = 0;
  CLI::Option* min_score_opt = nullptr;
};

void addQueryFlags(CLI::App* app, QueryFlags& q, bool with_rejected) {
  app->add_option("--top-k", q.top_k, "Loops to return (server default 5, at most 100)");
  app->add_option("--exclude-recent", q.exclude_recent,
                  "Skip the querying robot's scans within N sequence numbers in the same session (default 50)");
  app->add_option("--exclude-seconds", q.exclude_seconds,
                  "Skip the querying robot's scans within S seconds (needs stamps)");
  app->add_option("--scope", q.scope,
                  "same (this robot), other (other robots), all (default), sessions (see --sessions)");
  app->add_option("--sessions", q.sessions, "robot/session names searched with --scope sessions (comma separated)");
  app->add_option("--candidates", q.candidates, "Descriptor neighbours to verify (server default max(top-k, 10))");
  app->add_flag("--no-refine", q.no_refine, "Skip the fine/refine pose stages");
  if (with_rejected) {
    app->add_flag("--include-rejected", q.include_rejected, "Also list candidates that failed verification");
    app->add_option("--verify", q.verify_scan_ids, "Check exactly these stored scan ids instead of searching")
        ->delimiter(',');
    app->add_flag(
        "--known-loops", q.known_loops,
        "The candidates are known loops (with --verify: a chosen place): estimate a pose for rejected ones too");
  }
  q.min_score_opt = app->add_option("--min-score", q.min_score, "Drop verified candidates scoring below this");
}

v1::QueryOptions toQueryOptions(const QueryFlags& q) {
  v1::QueryOptions o;
  try {
    o.set_scope(sc::parseScope(q.scope));
  } catch (const sglc::InputError& e) {
    throw UsageError(std::string("--scope: ") + e.what());
  }
  if (q.scope == "sessions" && q.sessions.empty())
    throw UsageError("--scope sessions needs --sessions robot/session,...");
  if (q.scope != "sessions" && !q.sessions.empty()) throw UsageError("--sessions needs --scope sessions");
  std::istringstream list(q.sessions);
  for (std::string s; std::getline(list, s, ',');) {
    const auto slash = s.find('/');
    if (slash == std::string::npos || slash == 0 || slash + 1 == s.size())
      throw UsageError("--sessions: '" + s + "' is not robot/session");
    o.add_sessions(s);
  }
  if (q.exclude_recent < 0) throw UsageError("--exclude-recent must be >= 0");
  if (!(q.exclude_seconds >= 0)) throw UsageError("--exclude-seconds must be >= 0");
  o.set_exclude_recent(q.exclude_recent);
  o.set_exclude_seconds(q.exclude_seconds);
  o.set_top_k(q.top_k);
  o.set_candidates(q.candidates);
  if (q.no_refine) {
    o.set_refine(false);
    o.set_refine_set(true);
  }
  o.set_include_rejected(q.include_rejected);
  if (q.known_loops && q.no_refine) throw UsageError("--known-loops asks for poses: it cannot go with --no-refine");
  o.set_known_loops(q.known_loops);
  for (const auto id : q.verify_scan_ids) o.add_verify_scan_ids(id);
  if (q.min_score_opt && q.min_score_opt->count() > 0) o.set_min_score(q.min_score);
  return o;
}

// ---------------------------------------------------------------------------------------------------------
// Output helpers

json transformJson(const v1::Transform& t) {
  json a = json::array();
  for (double v : t.m()) a.push_back(v);
  return a;
}

// Translation and yaw of a transform, for the text output.
std::string poseText(const v1::Transform& t) {
  if (t.m_size() != 16) return "no pose";
  const auto& m = t.m();
  const double yaw = std::atan2(m[4], m[0]) * 180.0 / M_PI;
  std::ostringstream ss;
  ss << std::fixed << std::setprecision(2) << "t = (" << m[3] << ", " << m[7] << ", " << m[11] << ") m, yaw "
     << std::setprecision(1) << yaw << " deg";
  return ss.str();
}

json candidateJson(const v1::Candidate& c) {
  json j;
  j["scan_id"] = c.scan_id();
  j["robot"] = c.robot();
  j["session"] = c.session();
  j["seq"] = c.seq();
  j["score"] = c.score();
  j["verified"] = c.verified();
  j["inliers"] = c.inliers();
  j["fitness"] = c.fitness();
  j["rmse"] = c.rmse();
  j["refined"] = c.refined();
  j["descriptor_distance"] = c.descriptor_distance();
  j["T"] = transformJson(c.t_query_candidate());
  if (c.information_size() > 0) j["information"] = std::vector<double>(c.information().begin(), c.information().end());
  return j;
}

std::string candidateText(const v1::Candidate& c) {
  std::ostringstream ss;
  ss << "scan " << c.scan_id() << " (robot " << c.robot() << ", session " << c.session() << ", seq " << c.seq()
     << "): score " << std::fixed << std::setprecision(3) << c.score() << ", " << c.inliers() << " inliers"
     << (c.verified() ? "" : ", NOT verified") << ", " << poseText(c.t_query_candidate());
  return ss.str();
}

json timingJson(const v1::Timing& t) {
  json j;
  j["fingerprint"] = t.fingerprint_ms();
  j["store"] = t.store_ms();
  j["search"] = t.search_ms();
  j["verify"] = t.verify_ms();
  j["refine"] = t.refine_ms();
  j["total"] = t.total_ms();
  return j;
}

// ---------------------------------------------------------------------------------------------------------
// Progress bar (stderr)

class Progress {
 public:
  Progress(bool enabled, std::size_t total) : enabled_(enabled), total_(total), t0_(std::chrono::steady_clock::now()) {}
  void update(std::size_t done, std::size_t loops) {
    if (!enabled_) return;
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    const int width = 30;
    const int filled = total_ ? static_cast<int>(width * done / total_) : width;
    std::string bar(filled, '#');
    bar.resize(width, '.');
    std::fprintf(stderr, "\r\033[K[%s] %zu/%zu scans  %.1f/s  %zu loops", bar.c_str(), done, total_,
                 s > 0 ? done / s : 0.0, loops);
    std::fflush(stderr);
    shown_ = true;
  }
  // Removes the bar so that other output starts on a clean line.
  void clear() {
    if (!shown_) return;
    std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
    shown_ = false;
  }
  void done() {
    if (!shown_) return;
    std::fprintf(stderr, "\n");
    shown_ = false;
  }

 private:
  bool enabled_;
  std::size_t total_;
  std::chrono::steady_clock::time_point t0_;
  bool shown_ = false;
};

// ---------------------------------------------------------------------------------------------------------
// Subcommands

struct IngestArgs {
  std::string map, robot, session, dir, frames;
  int every = 1;
  bool query = false;
  bool store_raw = false;
  bool progress = false, no_progress = false;
  int window = 4;
  double chunk_mb = sc::kDefaultChunkBytes / 1e6;
  QueryFlags q;
};

int runIngest(const Common& common, const IngestArgs& a) {
  if (a.map.empty()) throw UsageError("--map is empty");
  if (a.robot.empty()) throw UsageError("--robot is empty");
  if (a.window < 1) throw UsageError("--window must be at least 1");
  if (!(a.chunk_mb >= 0.001 && a.chunk_mb <= 2000)) throw UsageError("--chunk-mb must be between 0.001 and 2000");
  const v1::QueryOptions query_options = toQueryOptions(a.q);
  const sglc::Sequence seq = sglc::openSequence(a.dir, sglc::FrameSelection::parse(a.frames), a.every);
  const std::string session = a.session.empty() ? seq.name : a.session;
  if (session.empty()) throw UsageError("cannot name the session after " + a.dir + ": give --session");

  const sc::Client client = connectClient(common, static_cast<std::size_t>(a.chunk_mb * 1e6));
  client.ensureMap(a.map);

  const bool tty = ::isatty(STDERR_FILENO) == 1;
  Progress progress(a.progress || (tty && !a.no_progress), seq.frames.size());
  progress.update(0, 0);

  sc::IngestSession stream = client.openSession();
  std::deque<std::string> pending_frames;
  std::size_t done = 0, loops = 0;
  auto handle = [&](const v1::IngestResponse& r) {
    const std::string frame = pending_frames.front();
    pending_frames.pop_front();
    ++done;
    loops += r.loops_size();
    if (common.json) {
      json j;
      j["scan_id"] = r.scan_id();
      j["frame"] = frame;
      j["loops"] = json::array();
      for (const auto& c : r.loops()) j["loops"].push_back(candidateJson(c));
      progress.clear();
      std::cout << j.dump() << std::endl;
    } else if (r.loops_size() > 0) {
      progress.clear();
      for (const auto& c : r.loops())
        std::cout << "frame " << frame << " (scan " << r.scan_id() << "): loop with " << candidateText(c) << "\n";
      std::cout.flush();
    }
    progress.update(done, loops);
  };

  std::string failure;
  try {
    for (const auto& f : seq.frames) {
      const sglc::LabelledScan scan = sglc::readScan(f.bin_path, f.label_path);
      sc::IngestOptions o;
      o.stamp = f.stamp;
      o.odometry_pose = f.pose;
      o.store_raw = a.store_raw;
      o.query = a.query;
      o.query_options = query_options;
      stream.send(sc::makeKey(a.map, a.robot, session, f.number), scan, o);
      pending_frames.push_back(f.name);
      while (stream.outstanding() >= static_cast<std::size_t>(a.window)) handle(stream.next());
    }
  } catch (const std::exception& e) {
    failure = e.what();
  }
  // Report every scan the server answered, even after a failure, then close the stream.
  try {
    while (stream.outstanding() > 0) handle(stream.next());
    stream.finish();
  } catch (const std::exception& e) {
    if (failure.empty()) failure = e.what();
  }
  if (!failure.empty()) {
    progress.clear();
    throw std::runtime_error(failure + " (after " + std::to_string(done) + " of " + std::to_string(seq.frames.size()) +
                             " scans were stored)");
  }
  progress.done();
  if (!common.json)
    std::cout << "ingested " << done << " scans from " << a.dir << " into map " << a.map << " (robot " << a.robot
              << ", session " << session << ")" << (a.query ? ", " + std::to_string(loops) + " loops" : "") << "\n";
  return 0;
}

struct QueryArgs {
  std::string map, scan, labels, robot, session;
  std::int64_t scan_id = 0, seq = 0;
  double stamp = 0;
  CLI::Option *scan_id_opt = nullptr, *stamp_opt = nullptr;
  QueryFlags q;
};

int runQuery(const Common& common, const QueryArgs& a) {
  if (a.map.empty()) throw UsageError("--map is empty");
  const bool by_id = a.scan_id_opt->count() > 0;
  const bool by_scan = !a.scan.empty() || !a.labels.empty();
  if (by_id == by_scan) throw UsageError("give either --scan-id ID or --scan BIN --labels LABEL");
  if (by_scan && (a.scan.empty() || a.labels.empty())) throw UsageError("--scan and --labels go together");
  v1::QueryRequest request;
  request.set_map(a.map);
  *request.mutable_options() = toQueryOptions(a.q);
  request.set_robot(a.robot);
  request.set_session(a.session);
  request.set_seq(a.seq);
  if (a.stamp_opt->count() > 0) request.set_stamp(a.stamp);
  if (by_id) {
    request.set_scan_id(a.scan_id);
  } else {
    sc::packScan(sglc::readScan(a.scan, a.labels), request.mutable_scan());
  }
  const sc::Client client = connectClient(common);
  const v1::QueryResponse r = client.query(request);
  if (common.json) {
    json j;
    j["candidates"] = json::array();
    for (const auto& c : r.candidates()) j["candidates"].push_back(candidateJson(c));
    j["timing_ms"] = timingJson(r.timing());
    std::cout << j.dump() << std::endl;
  } else {
    std::cout << r.candidates_size() << " candidate" << (r.candidates_size() == 1 ? "" : "s") << " in map " << a.map
              << " (" << std::fixed << std::setprecision(1) << r.timing().total_ms() << " ms)\n";
    int rank = 0;
    for (const auto& c : r.candidates()) std::cout << "  #" << ++rank << " " << candidateText(c) << "\n";
  }
  return 0;
}

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

int runCreateMap(const Common& common, const std::string& name) {
  const auto m = connectClient(common).createMap(name);
  if (common.json) {
    std::cout << mapJson(m).dump() << std::endl;
  } else {
    std::cout << "created map " << m.name() << "\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"sglc: client of the SGLC LiDAR loop-closure service"};
  app.require_subcommand(1);
  Common common;
  if (const char* s = std::getenv("SGLC_SERVER"); s && *s) common.server = s;
  if (const char* t = std::getenv("SGLC_TOKEN"); t && *t) common.token = t;
  addCommon(&app, common);

  IngestArgs ingest;
  auto* c_ingest = app.add_subcommand("ingest", "Store a SemanticKITTI-layout sequence directory as one robot session");
  addCommon(c_ingest, common);
  c_ingest->add_option("--map", ingest.map, "Map name (created if missing)")->required();
  c_ingest->add_option("--robot", ingest.robot, "Robot name")->required();
  c_ingest->add_option("--session", ingest.session, "Session name (default: the directory's base name)");
  c_ingest->add_option("--frames", ingest.frames,
                       "Frame numbers: a, a:b (b exclusive; a: and :b open-ended), a:b:s, or a comma-separated list");
  c_ingest->add_option("--every", ingest.every, "Ingest every N-th frame (default 1)");
  c_ingest->add_flag("--query", ingest.query, "Look for loops before each scan is stored and report them");
  c_ingest->add_flag("--store-raw", ingest.store_raw, "Also keep the raw clouds on the server");
  c_ingest->add_flag("--progress", ingest.progress, "Show the progress bar even when stderr is not a terminal");
  c_ingest->add_flag("--no-progress", ingest.no_progress, "Never show the progress bar");
  c_ingest->add_option("--window", ingest.window, "Scans in flight on the stream (default 4)");
  c_ingest->add_option("--chunk-mb", ingest.chunk_mb,
                       "Scans larger than this (packed) go through IngestChunked in pieces this size (default 3)");
  addQueryFlags(c_ingest, ingest.q, false);
  c_ingest->add_option("DIR", ingest.dir, "Sequence directory (velodyne/, labels/, optional poses.txt, times.txt)")
      ->required();

  QueryArgs query;
  auto* c_query =
      app.add_subcommand("query", "Find loops for a stored scan (--scan-id) or a scan file (relocalization)");
  addCommon(c_query, common);
  c_query->add_option("--map", query.map, "Map name")->required();
  query.scan_id_opt = c_query->add_option("--scan-id", query.scan_id, "A stored scan's id");
  c_query->add_option("--scan", query.scan, "KITTI .bin of a scan that is not stored");
  c_query->add_option("--labels", query.labels, "SemanticKITTI .label for --scan");
  c_query->add_option("--robot", query.robot, "Querying robot (scope and exclusions)");
  c_query->add_option("--session", query.session, "Querying robot's session");
  c_query->add_option("--seq", query.seq, "Query's sequence number in that session");
  query.stamp_opt = c_query->add_option("--stamp", query.stamp, "Query's time stamp in seconds");
  addQueryFlags(c_query, query.q, true);

  auto* c_maps = app.add_subcommand("maps", "List maps");
  addCommon(c_maps, common);

  std::string robots_map;
  auto* c_robots = app.add_subcommand("robots", "List a map's robots");
  addCommon(c_robots, common);
  c_robots->add_option("--map", robots_map, "Map name")->required();

  std::string sessions_map, sessions_robot;
  auto* c_sessions = app.add_subcommand("sessions", "List a map's sessions");
  addCommon(c_sessions, common);
  c_sessions->add_option("--map", sessions_map, "Map name")->required();
  c_sessions->add_option("--robot", sessions_robot, "Only this robot's sessions");

  std::int64_t scan_id = 0;
  bool scan_graph = false;
  auto* c_scan = app.add_subcommand("scan", "Show a stored scan");
  addCommon(c_scan, common);
  c_scan->add_option("ID", scan_id, "Scan id")->required();
  c_scan->add_flag("--graph", scan_graph, "Include the semantic graph nodes and the scan descriptor");

  std::string stats_map;
  std::string traj_map, traj_robot, traj_session, traj_out;
  auto* c_traj = app.add_subcommand("trajectory", "Write a robot's optimised poses (KITTI format)");
  addCommon(c_traj, common);
  c_traj->add_option("--map", traj_map, "Map")->required();
  c_traj->add_option("--robot", traj_robot, "Robot")->required();
  c_traj->add_option("--session", traj_session, "Only this session");
  c_traj->add_option("--out", traj_out, "Output file (one 3x4 row-major pose per line, map frame)")->required();
  auto* c_stats = app.add_subcommand("stats", "Database or map statistics");
  addCommon(c_stats, common);
  c_stats->add_option("--map", stats_map, "Only this map");

  std::string del_map, del_robot, del_session;
  auto* c_delete = app.add_subcommand("delete", "Delete a robot's scans, or one of its sessions");
  addCommon(c_delete, common);
  c_delete->add_option("--map", del_map, "Map name")->required();
  c_delete->add_option("--robot", del_robot, "Robot name")->required();
  c_delete->add_option("--session", del_session, "Only this session");

  std::string backup_path;
  auto* c_backup = app.add_subcommand("backup", "Online backup of the database to a new file on the server");
  addCommon(c_backup, common);
  c_backup->add_option("PATH", backup_path, "Destination on the server's filesystem (must not exist)")->required();

  std::string create_name;
  auto* c_create = app.add_subcommand("create-map", "Create an empty map");
  addCommon(c_create, common);
  c_create->add_option("MAP", create_name, "Map name")->required();

  // CLI11 reports an unknown subcommand as "A subcommand is required"; name it instead.
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--server" || arg == "--token" || arg == "--tls-ca" || arg == "--timeout") {
      ++i;  // its value
      continue;
    }
    if (!arg.empty() && arg[0] == '-') continue;
    bool known = false;
    std::string names;
    for (const auto* sub : app.get_subcommands({})) {
      known = known || sub->get_name() == arg;
      names += (names.empty() ? "" : ", ") + sub->get_name();
    }
    if (!known) {
      std::cerr << "sglc: error: unknown subcommand '" << oneLine(arg) << "' (expected one of " << names << ")"
                << std::endl;
      return 2;
    }
    break;
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "sglc: error: " << oneLine(e.what()) << " (see sglc --help)" << std::endl;
    return 2;
  }

  try {
    if (*c_ingest) return runIngest(common, ingest);
    if (*c_query) return runQuery(common, query);
    if (*c_maps) return runMaps(common);
    if (*c_robots) return runRobots(common, robots_map);
    if (*c_sessions) return runSessions(common, sessions_map, sessions_robot);
    if (*c_scan) return runScan(common, scan_id, scan_graph);
    if (*c_stats) return runStats(common, stats_map);
    if (*c_traj) return runTrajectory(common, traj_map, traj_robot, traj_session, traj_out);
    if (*c_delete) return runDelete(common, del_map, del_robot, del_session);
    if (*c_backup) return runBackup(common, backup_path);
    if (*c_create) return runCreateMap(common, create_name);
    throw UsageError("no subcommand");
  } catch (const UsageError& e) {
    std::cerr << "sglc: error: " << oneLine(e.what()) << " (see sglc --help)" << std::endl;
    return 2;
  } catch (const sc::RpcError& e) {
    std::cerr << "sglc: error: " << oneLine(e.what()) << " [server " << common.server << "]" << std::endl;
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "sglc: error: " << oneLine(e.what()) << std::endl;
    return 1;
  }
}
