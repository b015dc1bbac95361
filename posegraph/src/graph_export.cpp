#include "sglc/posegraph/graph_export.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <tuple>

#include "loop_weight.hpp"
#include "map_graph.hpp"
#include "relative_pose_error.hpp"
#include "sglc/mcap_writer.hpp"
#include "sglc/posegraph/foxglove_scene.hpp"
#include "sglc/rigid.hpp"
#include "sglc/version.hpp"

namespace sglc::posegraph {
namespace {

constexpr std::int64_t kAll = std::numeric_limits<std::int64_t>::max();

// Every scan with a usable odometry pose (as MapGraph takes them), of the chosen robots, by robot, session, seq.
std::vector<ExportedGraph::Node> nodesOf(const storage::MapStore& store, const std::string& map,
                                         const std::vector<std::string>& robots) {
  std::map<std::int64_t, Mat4d> frames;
  for (const auto& f : store.sessionFrames(map)) frames[f.session_id] = f.T_map_session;
  std::map<std::int64_t, Mat4d> optimised;
  for (const auto& p : store.optimisedPoses(map, "", "", 0, kAll)) optimised[p.scan_id] = p.pose;
  std::vector<ExportedGraph::Node> nodes;
  for (const auto& n : store.graphNodes(map)) {
    if (!n.odometry_pose || rigidMotionError(*n.odometry_pose)) continue;
    if (!robots.empty() && std::find(robots.begin(), robots.end(), n.robot) == robots.end()) continue;
    ExportedGraph::Node node{n.scan_id, n.robot, n.session, n.seq, n.stamp, *n.odometry_pose, *n.odometry_pose, false};
    if (const auto p = optimised.find(n.scan_id); p != optimised.end()) {
      node.pose = p->second;
      node.optimised = true;
    } else if (const auto f = frames.find(n.session_id); f != frames.end()) {
      node.pose = f->second * *n.odometry_pose;
    }
    nodes.push_back(std::move(node));
  }
  std::sort(nodes.begin(), nodes.end(), [](const auto& a, const auto& b) {
    return std::tie(a.robot, a.session, a.seq) < std::tie(b.robot, b.session, b.seq);
  });
  return nodes;
}

Mat6d informationOf(const Mat6d& sqrt_info) { return sqrt_info.transpose() * sqrt_info; }

// A pose as the solver's 7 parameters: quaternion x, y, z, w, then translation.
std::array<double, 7> parameters(const Mat4d& T) {
  const Eigen::Quaterniond q = Eigen::Quaterniond(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).normalized();
  return {q.x(), q.y(), q.z(), q.w(), T(0, 3), T(1, 3), T(2, 3)};
}

std::string csvQuoted(const std::string& s) {
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

// "x y z qx qy qz qw" of a pose, as g2o writes it.
std::string poseG2o(const Mat4d& T) {
  const Eigen::Quaterniond q(Eigen::Matrix3d(T.topLeftCorner<3, 3>()));
  char buf[256];
  std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g %.17g %.17g %.17g %.17g", T(0, 3), T(1, 3), T(2, 3), q.x(), q.y(),
                q.z(), q.w());
  return buf;
}

std::vector<double> values(const Mat4d& T) {
  std::vector<double> v(16);
  for (int k = 0; k < 16; ++k) v[k] = T(k / 4, k % 4);
  return v;
}

}  // namespace

ExportedGraph exportGraph(const storage::MapStore& store, const std::string& map, const GraphOptimiserOptions& options,
                          const std::vector<std::string>& robots) {
  ExportedGraph g;
  g.graph_version = store.graphVersion(map);
  const auto loops = store.loops(map);  // read before the nodes: a loop's ends are stored before it
  g.nodes = nodesOf(store, map, robots);
  std::map<std::int64_t, std::size_t> index;
  for (std::size_t i = 0; i < g.nodes.size(); ++i) index[g.nodes[i].scan_id] = i;

  for (std::size_t i = 1; i < g.nodes.size(); ++i) {
    const auto &a = g.nodes[i - 1], &b = g.nodes[i];
    if (a.robot != b.robot || a.session != b.session) continue;
    ExportedGraph::Edge e;
    e.from = i - 1;
    e.to = i;
    e.T = a.odometry.inverse() * b.odometry;
    e.information =
        informationOf(odometrySqrtInformation(e.T, options.odometry_sigma_m, options.odometry_sigma_per_m,
                                              options.odometry_sigma_deg, options.odometry_sigma_deg_per_m));
    g.edges.push_back(e);
  }
  for (const auto& l : loops) {
    const auto a = index.find(l.query_scan), b = index.find(l.candidate_scan);
    std::optional<std::string> why = loopError(l);
    if (!why && (a == index.end() || b == index.end())) {
      const auto missing = a == index.end() ? l.query_scan : l.candidate_scan;
      const auto info = store.scanInfo(missing);
      if (!info)
        why = "scan " + std::to_string(missing) + " was deleted";
      else if (!robots.empty() && std::find(robots.begin(), robots.end(), info->robot) == robots.end())
        why = "scan " + std::to_string(missing) + " is robot '" + info->robot + "''s, not exported";
      else
        why = "scan " + std::to_string(missing) + " has no odometry pose (no graph node)";
    }
    if (why) {
      g.left_out.push_back({l, *why});
      continue;
    }
    ExportedGraph::Edge e;
    e.from = a->second;
    e.to = b->second;
    e.T = orthonormalised(l.T);
    const Mat6d sqrt_info =
        loopEdgeSqrtInformation(l.information, l.rmse, options.loop_sigma_m, options.loop_sigma_deg);
    // The server solves loops under a Cauchy loss of scale c: at its solution that is plain least squares with
    // each loop weighted by rho'(s) = 1 / (1 + s / c^2), s the loop's whitened squared error there. Exported
    // with that weight, the file's least-squares solution is the server's, and a loop it discounted stays so.
    const double c = options.loss_scale * loopLossFactor(l.probability, options.trusted_probability);
    const double s2 = relativePoseError(e.T, sqrt_info)
                          .squaredError(parameters(g.nodes[e.from].pose).data(), parameters(g.nodes[e.to].pose).data());
    e.weight = 1.0 / (1.0 + s2 / (c * c));
    e.information = e.weight * informationOf(sqrt_info);
    e.loop_id = l.id;
    e.probability = l.probability;
    e.score = l.score;
    g.edges.push_back(e);
  }
  return g;
}

void writeG2o(const ExportedGraph& graph, std::ostream& g2o, std::ostream& ids) {
  ids << "id,scan_id,robot,session,seq,stamp,optimised\n";
  char buf[64];
  for (std::size_t i = 0; i < graph.nodes.size(); ++i) {
    const auto& n = graph.nodes[i];
    g2o << "VERTEX_SE3:QUAT " << i << " " << poseG2o(n.pose) << "\n";
    ids << i << "," << n.scan_id << "," << csvQuoted(n.robot) << "," << csvQuoted(n.session) << "," << n.seq << ",";
    if (n.stamp) {
      std::snprintf(buf, sizeof buf, "%.17g", *n.stamp);
      ids << buf;
    }
    ids << "," << (n.optimised ? 1 : 0) << "\n";
  }
  Eigen::Matrix<double, 6, 1> scale;
  scale << 1, 1, 1, 2, 2, 2;  // g2o's rotation error is half ours: its information four times
  for (const auto& e : graph.edges) {
    const Mat6d info = scale.asDiagonal() * e.information * scale.asDiagonal();
    g2o << "EDGE_SE3:QUAT " << e.from << " " << e.to << " " << poseG2o(e.T);
    for (int r = 0; r < 6; ++r)
      for (int c = r; c < 6; ++c) {
        std::snprintf(buf, sizeof buf, " %.17g", 0.5 * (info(r, c) + info(c, r)));
        g2o << buf;
      }
    g2o << "\n";
  }
}

void writeLeftOutCsv(const ExportedGraph& graph, std::ostream& out) {
  out << "loop_id,query_scan,candidate_scan,reason\n";
  for (const auto& l : graph.left_out)
    out << l.loop.id << "," << l.loop.query_scan << "," << l.loop.candidate_scan << "," << csvQuoted(l.reason) << "\n";
}

void writeGraphJson(const ExportedGraph& graph, std::ostream& out) {
  nlohmann::ordered_json j;
  j["graph_version"] = graph.graph_version;
  auto& nodes = j["nodes"] = nlohmann::ordered_json::array();
  for (const auto& n : graph.nodes)
    nodes.push_back({{"scan_id", n.scan_id},
                     {"robot", n.robot},
                     {"session", n.session},
                     {"seq", n.seq},
                     {"stamp", n.stamp ? nlohmann::ordered_json(*n.stamp) : nlohmann::ordered_json(nullptr)},
                     {"optimised", n.optimised},
                     {"pose", values(n.pose)},
                     {"odometry", values(n.odometry)}});
  auto& edges = j["edges"] = nlohmann::ordered_json::array();
  for (const auto& e : graph.edges) {
    std::vector<double> info(36);
    for (int k = 0; k < 36; ++k) info[k] = e.information(k / 6, k % 6);
    nlohmann::ordered_json o = {{"from", e.from}, {"to", e.to}, {"kind", e.loop_id ? "loop" : "odometry"}};
    if (e.loop_id) o["loop_id"] = e.loop_id;
    if (e.probability) o["probability"] = *e.probability;
    if (e.loop_id) o["robust_weight"] = e.weight;
    o["T"] = values(e.T);
    o["information"] = info;
    edges.push_back(std::move(o));
  }
  auto& left = j["left_out"] = nlohmann::ordered_json::array();
  for (const auto& l : graph.left_out)
    left.push_back({{"loop_id", l.loop.id},
                    {"query_scan", l.loop.query_scan},
                    {"candidate_scan", l.loop.candidate_scan},
                    {"T", values(l.loop.T)},
                    {"reason", l.reason}});
  out << j.dump(1) << "\n";
}

}  // namespace sglc::posegraph

namespace sglc::posegraph {
std::size_t writeGraphMcap(const ExportedGraph& graph, std::ostream& out, const ScanPoints& points, double voxel_m) {
  const auto stamp_ns = newestStampNs(graph);
  McapWriter mcap(out, "", std::string("sglc ") + kVersion);
  std::map<std::string, std::uint16_t> schema_ids;
  for (const auto& t : foxgloveScene(graph, stamp_ns)) {
    auto schema = schema_ids.find(t.schema_name);
    if (schema == schema_ids.end())
      schema =
          schema_ids.emplace(t.schema_name, mcap.addSchema(t.schema_name, "jsonschema", foxgloveSchema(t.schema_name)))
              .first;
    const auto channel = mcap.addChannel(schema->second, "/sglc/" + t.topic, "json");
    mcap.addMessage(channel, stamp_ns, t.message);
  }
  std::size_t keyframes = 0;
  if (points) {
    constexpr std::size_t kMaxKeyframePoints = 100000;
    std::size_t bytes = 0;
    std::map<std::string, std::uint16_t> channels;
    for (const auto& n : graph.nodes) {
      if (bytes >= kMaxKeyframeBytes) break;  // the file stays a size one can download and open
      const auto cloud = points(n.scan_id);
      if (!cloud) continue;
      auto channel = channels.find(n.robot);
      if (channel == channels.end()) {
        if (!schema_ids.count("foxglove.PointCloud"))
          schema_ids["foxglove.PointCloud"] =
              mcap.addSchema("foxglove.PointCloud", "jsonschema", foxgloveSchema("foxglove.PointCloud"));
        channel = channels
                      .emplace(n.robot, mcap.addChannel(schema_ids["foxglove.PointCloud"],
                                                        "/sglc/keyframes/" + topicName(n.robot), "json"))
                      .first;
      }
      const auto at =
          n.stamp && *n.stamp > 0 && *n.stamp < 1.8e10 ? static_cast<std::uint64_t>(*n.stamp * 1e9) : stamp_ns;
      const auto message = foxglovePointCloud(*cloud, n.pose, at, voxel_m, kMaxKeyframePoints);
      mcap.addMessage(channel->second, at, message);
      bytes += message.size();
      ++keyframes;
    }
  }
  mcap.finish();
  return keyframes;
}

}  // namespace sglc::posegraph
