#include "common.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "sglc/client/packing.hpp"

namespace sglc::cli {

std::string oneLine(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  std::replace(s.begin(), s.end(), '\r', ' ');
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

// ---------------------------------------------------------------------------------------------------------
// Options shared by every subcommand

void addCommon(CLI::App* app, Common& c) {
  app->add_option("--server", c.server, "Server address host:port (default 127.0.0.1:50051, or $SGLC_SERVER)");
  app->add_option("--token", c.token, "Bearer token (default $SGLC_TOKEN)");
  app->add_option("--tls-ca", c.tls_ca, "PEM file of root certificates: use TLS and verify the server with them");
  app->add_option("--timeout", c.timeout_s, "Deadline of each call in seconds (default 30; 0: none)");
  app->add_flag("--json", c.json, "Machine-readable output (JSON)");
}

sc::Client connectClient(const Common& c, std::size_t chunk_bytes, int max_attempts) {
  sc::ConnectOptions options;
  options.chunk_bytes = chunk_bytes;
  options.max_attempts = max_attempts;
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
  app->add_flag("--evidence", q.evidence, "Show what the loop model measured for each candidate (its evidence)");
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
  o.set_include_evidence(q.evidence);
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
  j["probability"] = c.has_probability() ? json(c.probability()) : json(nullptr);  // null: an older server
  j["verified"] = c.verified();
  j["inliers"] = c.inliers();
  j["fitness"] = c.fitness();
  j["rmse"] = c.rmse();
  j["refined"] = c.refined();
  j["descriptor_distance"] = c.descriptor_distance();
  j["T"] = transformJson(c.t_query_candidate());
  if (c.information_size() > 0) j["information"] = std::vector<double>(c.information().begin(), c.information().end());
  if (c.has_evidence()) j["evidence"] = evidenceJson(c.evidence());
  if (!c.reason().empty()) j["reason"] = c.reason();
  return j;
}

json evidenceJson(const v1::Evidence& e) {
  json j;
  std::string source = v1::EvidenceSource_Name(e.source());  // "" for a value newer than this client
  j["source"] = source.empty() ? std::to_string(e.source()) : source.substr(std::string("EVIDENCE_SOURCE_").size());
  j["landmarks"] = e.landmarks();
  j["landmark_similarity"] = e.landmark_similarity();
  j["field_deg"] = e.field_deg();
  j["agreement"] = e.agreement();
  j["wide_agreement"] = e.wide_agreement();
  j["pin"] = e.pin();
  j["plane_overlap"] = e.plane_overlap();
  j["plane_rmse_m"] = e.plane_rmse_m();
  j["constraint"] = e.constraint();
  j["context_similarity"] = e.context_similarity();
  j["translation_m"] = e.translation_m();
  return j;
}

std::string candidateText(const v1::Candidate& c) {
  std::ostringstream ss;
  ss << "scan " << c.scan_id() << " (robot " << c.robot() << ", session " << c.session() << ", seq " << c.seq()
     << "): score " << std::fixed << std::setprecision(3) << c.score() << ", probability ";
  if (c.has_probability())
    ss << c.probability();
  else
    ss << "unknown";
  ss << ", " << c.inliers() << " inliers"
     << (c.verified() ? "" : ", NOT verified" + (c.reason().empty() ? std::string() : " (" + c.reason() + ")")) << ", "
     << poseText(c.t_query_candidate());
  if (c.has_evidence()) ss << "\n      evidence " << evidenceJson(c.evidence()).dump();
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

}  // namespace sglc::cli
