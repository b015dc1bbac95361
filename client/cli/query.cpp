// `sglc query`: loops for a stored scan, or for a scan file that is not stored (relocalization).
#include <iostream>
#include <memory>

#include "common.hpp"
#include "sglc/client/packing.hpp"
#include "sglc/io.hpp"

namespace sglc::cli {
namespace {

struct QueryArgs {
  std::string map, scan, labels, robot, session;
  std::string label_field = "label";
  std::int64_t scan_id = 0, seq = 0;
  double stamp = 0;
  CLI::Option *scan_id_opt = nullptr, *stamp_opt = nullptr;
  QueryFlags q;
};

int runQuery(const Common& common, const QueryArgs& a) {
  if (a.map.empty()) throw UsageError("--map is empty");
  const bool by_id = a.scan_id_opt->count() > 0;
  const bool by_scan = !a.scan.empty();
  if (!by_scan && !a.labels.empty()) throw UsageError("--labels goes with --scan");
  if (by_id == by_scan) throw UsageError("give either --scan-id ID or --scan FILE [--labels FILE]");
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
    sc::packScan(sglc::readScan(a.scan, a.labels, a.label_field), request.mutable_scan());
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

}  // namespace

void addQuery(CLI::App& app, Common& common, Commands& out) {
  auto a = std::make_shared<QueryArgs>();
  auto* c = app.add_subcommand("query", "Find loops for a stored scan (--scan-id) or a scan file (relocalization)");
  addCommon(c, common);
  c->add_option("--map", a->map, "Map name")->required();
  a->scan_id_opt = c->add_option("--scan-id", a->scan_id, "A stored scan's id");
  c->add_option("--scan", a->scan, "A scan that is not stored: .bin, .pcd, .ply or .npy");
  c->add_option("--labels", a->labels,
                "Labels of --scan (.label or .npy; absent: the file's own or the server's labeller)");
  c->add_option("--label-field", a->label_field, "Label field of a PCD/PLY --scan")->capture_default_str();
  c->add_option("--robot", a->robot, "Querying robot (scope and exclusions)");
  c->add_option("--session", a->session, "Querying robot's session");
  c->add_option("--seq", a->seq, "Query's sequence number in that session");
  a->stamp_opt = c->add_option("--stamp", a->stamp, "Query's time stamp in seconds");
  addQueryFlags(c, a->q, true);
  out.push_back({c, [&common, a] { return runQuery(common, *a); }});
}

}  // namespace sglc::cli
