#include "sglc/posegraph/foxglove_scene.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <tuple>
#include <unordered_set>

namespace sglc::posegraph {
namespace {

using Json = nlohmann::ordered_json;

// Short JSON Schemas (Foxglove identifies its types by name; these say their shape).
const char* const kVector3 =
    R"({"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}})";
const char* const kTime = R"({"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}})";
const char* const kQuaternion =
    R"({"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},)"
    R"("w":{"type":"number"}}})";

std::string poseSchema() {
  return std::string(R"({"type":"object","properties":{"position":)") + kVector3 + R"(,"orientation":)" + kQuaternion +
         "}}";
}

std::map<std::string, std::string> schemas() {
  std::map<std::string, std::string> s;
  s["foxglove.PosesInFrame"] = std::string(R"({"title":"foxglove.PosesInFrame","type":"object","properties":{)") +
                               R"("timestamp":)" + kTime + R"(,"frame_id":{"type":"string"},)" +
                               R"("poses":{"type":"array","items":)" + poseSchema() + "}}}";
  s["foxglove.SceneUpdate"] =
      std::string(R"({"title":"foxglove.SceneUpdate","type":"object","properties":{"deletions":{"type":"array"},)"
                  R"("entities":{"type":"array","items":{"type":"object","properties":{"timestamp":)") +
      kTime + R"(,"frame_id":{"type":"string"},"id":{"type":"string"},"lifetime":)" + kTime +
      R"(,"frame_locked":{"type":"boolean"},"metadata":{"type":"array"},"lines":{"type":"array"}}}}}})";
  s["foxglove.PointCloud"] =
      std::string(R"({"title":"foxglove.PointCloud","type":"object","properties":{"timestamp":)") + kTime +
      R"(,"frame_id":{"type":"string"},"pose":)" + poseSchema() +
      R"(,"point_stride":{"type":"integer"},"fields":{"type":"array","items":{"type":"object","properties":{)"
      R"("name":{"type":"string"},"offset":{"type":"integer"},"type":{"type":"integer"}}}},)"
      R"("data":{"type":"string","contentEncoding":"base64"}}})";
  const char* const kEnd = R"({"type":"object","properties":{"robot":{"type":"string"},"session":{"type":"string"},)"
                           R"("seq":{"type":"integer"},"scan_id":{"type":"integer"}}})";
  s["sglc.LoopList"] = std::string(R"({"title":"sglc.LoopList","type":"object","properties":{)") +
                       R"("graph_version":{"type":"integer"},"loops":{"type":"array","items":{"type":"object",)" +
                       R"("properties":{"id":{"type":"integer"},"from":)" + kEnd + R"(,"to":)" + kEnd +
                       R"(,"inter_robot":{"type":"boolean"},"score":{"type":"number"},)"
                       R"("probability":{"type":["number","null"]},"weight":{"type":"number"}}}}}})";
  s["sglc.MapEvent"] = R"({"title":"sglc.MapEvent","type":"object","properties":{"graph_version":{"type":"integer"},)"
                       R"("nodes":{"type":"integer"},"loops":{"type":"integer"},"rejected_loops":{"type":"integer"},)"
                       R"("optimise_ms":{"type":"number"},"converged":{"type":"boolean"},"global":{"type":"boolean"},)"
                       R"("failed":{"type":"boolean"},"error":{"type":"string"}}})";
  s["sglc.MapStats"] = R"({"title":"sglc.MapStats","type":"object","properties":{"scans":{"type":"integer"},)"
                       R"("places":{"type":"integer"},"versions":{"type":"integer"},)"
                       R"("retired_scans":{"type":"integer"},"retired_bytes":{"type":"integer"}}})";
  return s;
}

Json timeOf(std::uint64_t ns) { return {{"sec", ns / 1000000000ULL}, {"nsec", ns % 1000000000ULL}}; }

Json poseJson(const Mat4d& T) {
  const Eigen::Quaterniond q = Eigen::Quaterniond(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).normalized();
  return {{"position", {{"x", T(0, 3)}, {"y", T(1, 3)}, {"z", T(2, 3)}}},
          {"orientation", {{"x", q.x()}, {"y", q.y()}, {"z", q.z()}, {"w", q.w()}}}};
}

Json pointJson(const Mat4d& T) { return {{"x", T(0, 3)}, {"y", T(1, 3)}, {"z", T(2, 3)}}; }

Json endJson(const ExportedGraph::Node& n) {
  return {{"robot", n.robot}, {"session", n.session}, {"seq", n.seq}, {"scan_id", n.scan_id}};
}

std::string base64(const unsigned char* data, std::size_t size) {
  static const char* const kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((size + 2) / 3 * 4);
  for (std::size_t i = 0; i < size; i += 3) {
    const std::uint32_t n = (std::uint32_t{data[i]} << 16) | (i + 1 < size ? std::uint32_t{data[i + 1]} << 8 : 0U) |
                            (i + 2 < size ? std::uint32_t{data[i + 2]} : 0U);
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += i + 1 < size ? kAlphabet[(n >> 6) & 63] : '=';
    out += i + 2 < size ? kAlphabet[n & 63] : '=';
  }
  return out;
}

// The loops of the graph as two line-list entities (intra-robot green, inter-robot red).
Json loopEntities(const ExportedGraph& graph, std::uint64_t stamp_ns) {
  struct Kind {
    const char* id;
    Json colour;
    Json points = Json::array();
    double probability_sum = 0;
    int with_probability = 0;
  };
  Kind intra{"intra-robot loops", {{"r", 0.1}, {"g", 0.7}, {"b", 0.2}, {"a", 1.0}}};
  Kind inter{"inter-robot loops", {{"r", 0.9}, {"g", 0.1}, {"b", 0.1}, {"a", 1.0}}};
  for (const auto& e : graph.edges) {
    if (!e.loop_id) continue;
    auto& kind = graph.nodes[e.from].robot == graph.nodes[e.to].robot ? intra : inter;
    kind.points.push_back(pointJson(graph.nodes[e.from].pose));
    kind.points.push_back(pointJson(graph.nodes[e.to].pose));
    if (e.probability) {
      kind.probability_sum += *e.probability;
      ++kind.with_probability;
    }
  }
  Json entities = Json::array();
  for (const Kind* kind : {&intra, &inter}) {
    Json line = {{"type", 2},  // LINE_LIST
                 {"pose", poseJson(Mat4d::Identity())},
                 {"thickness", 2.0},
                 {"scale_invariant", true},
                 {"points", kind->points},
                 {"color", kind->colour},
                 {"colors", Json::array()},
                 {"indices", Json::array()}};
    Json metadata = Json::array({{{"key", "loops"}, {"value", std::to_string(kind->points.size() / 2)}}});
    if (kind->with_probability) {
      char mean[32];
      std::snprintf(mean, sizeof mean, "%.3f", kind->probability_sum / kind->with_probability);
      metadata.push_back({{"key", "mean probability"}, {"value", mean}});
    }
    entities.push_back({{"timestamp", timeOf(stamp_ns)},
                        {"frame_id", "map"},
                        {"id", kind->id},
                        {"lifetime", timeOf(0)},
                        {"frame_locked", false},
                        {"metadata", metadata},
                        {"arrows", Json::array()},
                        {"cubes", Json::array()},
                        {"spheres", Json::array()},
                        {"cylinders", Json::array()},
                        {"lines", Json::array({line})},
                        {"triangles", Json::array()},
                        {"texts", Json::array()},
                        {"models", Json::array()}});
  }
  return entities;
}

Json loopList(const ExportedGraph& graph) {
  Json loops = Json::array();
  for (const auto& e : graph.edges) {
    if (!e.loop_id) continue;
    const auto &a = graph.nodes[e.from], &b = graph.nodes[e.to];
    loops.push_back({{"id", e.loop_id},
                     {"from", endJson(a)},
                     {"to", endJson(b)},
                     {"inter_robot", a.robot != b.robot},
                     {"score", e.score},
                     {"probability", e.probability ? Json(*e.probability) : Json(nullptr)},
                     {"weight", e.weight}});
  }
  return {{"graph_version", graph.graph_version}, {"loops", loops}};
}

}  // namespace

const std::string& foxgloveSchema(const std::string& schema_name) {
  static const auto kSchemas = schemas();
  const auto it = kSchemas.find(schema_name);
  if (it == kSchemas.end()) throw std::invalid_argument("no schema named '" + schema_name + "'");
  return it->second;
}

std::string topicName(const std::string& name) {
  std::string out;
  for (const char c : name) {
    if (c == '%')
      out += "%25";
    else if (c == '/')
      out += "%2F";
    else
      out += c;
  }
  return out;
}

std::uint64_t newestStampNs(const ExportedGraph& graph) {
  std::uint64_t stamp_ns = 0;
  for (const auto& n : graph.nodes)
    if (n.stamp && *n.stamp > 0 && *n.stamp < 1.8e10)
      stamp_ns = std::max(stamp_ns, static_cast<std::uint64_t>(*n.stamp * 1e9));
  return stamp_ns;
}

std::vector<FoxgloveTopic> foxgloveScene(const ExportedGraph& graph, std::uint64_t stamp_ns) {
  std::vector<FoxgloveTopic> out;
  std::map<std::string, std::vector<std::size_t>> by_robot;
  for (std::size_t i = 0; i < graph.nodes.size(); ++i) by_robot[graph.nodes[i].robot].push_back(i);
  // The map frame of each session: pose = frame * odometry for every node, so frame = pose * odometry^-1 of its
  // first node (exact for scans not yet optimised; for optimised ones, the odometry as placed at the first).
  for (const auto& [robot, idx] : by_robot) {
    Json trajectory = {{"timestamp", timeOf(stamp_ns)}, {"frame_id", "map"}, {"poses", Json::array()}};
    Json odometry = trajectory;
    const ExportedGraph::Node* first = nullptr;
    Mat4d frame = Mat4d::Identity();
    for (const auto i : idx) {
      const auto& n = graph.nodes[i];
      if (!first || first->session != n.session) {
        first = &n;
        frame = n.pose * n.odometry.inverse();
      }
      trajectory["poses"].push_back(poseJson(n.pose));
      odometry["poses"].push_back(poseJson(frame * n.odometry));
    }
    out.push_back({"trajectory/" + topicName(robot), "foxglove.PosesInFrame", trajectory.dump()});
    out.push_back({"odometry/" + topicName(robot), "foxglove.PosesInFrame", odometry.dump()});
  }
  out.push_back({"loops", "foxglove.SceneUpdate",
                 Json({{"deletions", Json::array()}, {"entities", loopEntities(graph, stamp_ns)}}).dump()});
  out.push_back({"loop_list", "sglc.LoopList", loopList(graph).dump()});
  return out;
}

std::string foxglovePointCloud(const Points& points, const Mat4d& pose, std::uint64_t stamp_ns, double voxel_m,
                               std::size_t max_points) {
  if (!(voxel_m > 0)) throw std::invalid_argument("the voxel size must be positive");
  constexpr double kReach = 5e5;  // m: cells of packCell cover +-2^20 voxels
  std::vector<float> kept;
  VoxelMap voxels(std::min<std::size_t>(points.size(), 1 << 16));
  for (const auto& p : points) {
    if (kept.size() / 3 >= max_points) break;
    if (!p.allFinite() || p.cast<double>().cwiseAbs().maxCoeff() > std::min(kReach, voxel_m * (1 << 19))) continue;
    bool fresh = false;
    voxels.findOrInsert(
        packCell(static_cast<int>(std::floor(p.x() / voxel_m)), static_cast<int>(std::floor(p.y() / voxel_m)),
                 static_cast<int>(std::floor(p.z() / voxel_m))),
        0, &fresh);
    if (fresh) kept.insert(kept.end(), {p.x(), p.y(), p.z()});
  }
  Json fields = Json::array();
  for (const auto& [name, offset] : {std::pair<const char*, int>{"x", 0}, {"y", 4}, {"z", 8}})
    fields.push_back({{"name", name}, {"offset", offset}, {"type", 7}});  // FLOAT32, little-endian
  return Json({{"timestamp", timeOf(stamp_ns)},
               {"frame_id", "map"},
               {"pose", poseJson(pose)},
               {"point_stride", 12},
               {"fields", fields},
               {"data", base64(reinterpret_cast<const unsigned char*>(kept.data()), kept.size() * sizeof(float))}})
      .dump();
}

std::string foxgloveMapEvent(const GraphEvent& event) {
  return Json({{"graph_version", event.graph_version},
               {"nodes", event.nodes},
               {"loops", event.loops},
               {"rejected_loops", event.rejected_loops},
               {"optimise_ms", event.optimise_ms},
               {"converged", event.converged},
               {"global", event.global},
               {"failed", event.failed},
               {"error", event.error}})
      .dump();
}

std::string foxgloveMapStats(const storage::Stats& stats) {
  return Json({{"scans", stats.scans},
               {"places", stats.places},
               {"versions", stats.versions},
               {"retired_scans", stats.retired_scans},
               {"retired_bytes", stats.retired_bytes}})
      .dump();
}

}  // namespace sglc::posegraph
