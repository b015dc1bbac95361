#include "sglc/client/export_formats.hpp"

#include <cstdio>

namespace sglc::client {
namespace {

nlohmann::ordered_json endJson(const v1::LoopEnd& e) {
  return {{"scan_id", e.scan_id()}, {"robot", e.robot()}, {"session", e.session()}, {"seq", e.seq()}};
}

}  // namespace

nlohmann::ordered_json loopJson(const v1::LoopEdge& l) {
  nlohmann::ordered_json j;
  j["id"] = l.id();
  j["query"] = endJson(l.query());
  j["candidate"] = endJson(l.candidate());
  j["score"] = l.score();
  // null: recorded before the loop model (unknown).
  j["probability"] = l.has_probability() ? nlohmann::ordered_json(l.probability()) : nlohmann::ordered_json(nullptr);
  j["inliers"] = l.inliers();
  j["fitness"] = l.fitness();
  j["rmse"] = l.rmse();
  j["T"] = std::vector<double>(l.t_query_candidate().m().begin(), l.t_query_candidate().m().end());
  if (l.information_size() > 0) j["information"] = std::vector<double>(l.information().begin(), l.information().end());
  return j;
}

void writeLoopsCsv(const std::vector<v1::LoopEdge>& loops, std::ostream& out) {
  // Robot and session names may hold commas or quotes: quoted per RFC 4180.
  auto quoted = [](const std::string& s) {
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
  };
  out << "id,query_scan,query_robot,query_session,query_seq,candidate_scan,candidate_robot,candidate_session,"
         "candidate_seq,score,probability,inliers,fitness,rmse";
  for (int k = 0; k < 16; ++k) out << ",T" << k / 4 << k % 4;
  out << ",has_information\n";
  char buf[64];
  for (const auto& l : loops) {
    out << l.id() << "," << l.query().scan_id() << "," << quoted(l.query().robot()) << ","
        << quoted(l.query().session()) << "," << l.query().seq() << "," << l.candidate().scan_id() << ","
        << quoted(l.candidate().robot()) << "," << quoted(l.candidate().session()) << "," << l.candidate().seq();
    std::snprintf(buf, sizeof buf, ",%.9g,", l.score());
    out << buf;
    if (l.has_probability()) {  // empty: recorded before the loop model (unknown)
      std::snprintf(buf, sizeof buf, "%.17g", l.probability());
      out << buf;
    }
    for (double v : {double(l.inliers()), l.fitness(), l.rmse()}) {
      std::snprintf(buf, sizeof buf, ",%.9g", v);
      out << buf;
    }
    for (double v : l.t_query_candidate().m()) {
      std::snprintf(buf, sizeof buf, ",%.17g", v);  // round-trips a double
      out << buf;
    }
    out << "," << (l.information_size() == 36 ? 1 : 0) << "\n";
  }
}

}  // namespace sglc::client
