// The PoseGraph service's handlers: optimised poses, session frames and the loops of a map's pose graph
// (WatchMap, a stream, is in streams.cpp).
#include <algorithm>
#include <map>
#include <optional>
#include <sstream>

#include "call.hpp"
#include "rpc_error.hpp"
#include "service.hpp"
#include "sglc/posegraph/graph_export.hpp"
#include "sglc/wire/geometry_codec.hpp"

namespace sglc::server {
namespace {

// The ends of loops as the wire names them, looked up once per scan (nullptr: the scan is gone).
class LoopEnds {
 public:
  explicit LoopEnds(const storage::MapStore& store) : store_(store) {}
  const v1::LoopEnd* find(std::int64_t scan_id) {
    auto it = ends_.find(scan_id);
    if (it == ends_.end()) {
      std::optional<v1::LoopEnd> end;
      if (const auto info = store_.scanInfo(scan_id)) {
        end.emplace();
        end->set_scan_id(scan_id);
        end->set_robot(info->robot);
        end->set_session(info->session);
        end->set_seq(info->seq);
      }
      it = ends_.emplace(scan_id, std::move(end)).first;
    }
    return it->second ? &*it->second : nullptr;
  }

 private:
  const storage::MapStore& store_;
  std::map<std::int64_t, std::optional<v1::LoopEnd>> ends_;
};

void toWire(const storage::LoopRecord& l, const v1::LoopEnd& query, const v1::LoopEnd& candidate, v1::LoopEdge* o) {
  o->set_id(l.id);
  *o->mutable_query() = query;
  *o->mutable_candidate() = candidate;
  wire::toTransform(l.T, o->mutable_t_query_candidate());
  o->set_score(l.score);
  o->set_inliers(l.inliers);
  o->set_fitness(l.fitness);
  o->set_rmse(l.rmse);
  if (l.probability) o->set_probability(*l.probability);  // absent: recorded before the loop model
  if (l.information)
    for (int k = 0; k < 36; ++k) o->add_information((*l.information)(k / 6, k % 6));
}

std::int64_t pageSize(std::uint32_t requested) {
  if (requested > 10000) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "page_size must be at most 10000");
  return requested ? requested : 1000;
}

}  // namespace

storage::MapInfo requireMap(const ServiceState& state, const grpc::ServerContextBase* ctx, const std::string& map) {
  wire::checkName("map", map);
  TokenTable::require(state.tokens().authenticate(*ctx), map);
  auto info = state.store().findMap(map);
  if (!info) throw RpcError(grpc::StatusCode::NOT_FOUND, "no map named '" + map + "'");
  return *std::move(info);
}

void checkFilterName(const std::string& what, const std::string& name) {
  if (!name.empty()) wire::checkName(what, name);
}

grpc::Status PoseGraphService::GetPoses(grpc::ServerContext* ctx, const v1::GetPosesRequest* req,
                                        v1::GetPosesResponse* resp) {
  return run(ctx, {"GetPoses", req->map(), req->robot()}, [&](CallLog&) {
    requireMap(state_, ctx, req->map());
    checkFilterName("robot", req->robot());
    checkFilterName("session", req->session());
    if (!req->session().empty() && req->robot().empty())
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "a session needs its robot");
    if (req->page_token() < 0) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "page_token must be >= 0");
    const std::int64_t page = pageSize(req->page_size());
    auto& store = state_.store();
    if (!req->robot().empty()) {
      bool found = false;
      for (const auto& s : store.listSessions(req->map(), req->robot()))
        found = found || req->session().empty() || s.name == req->session();
      if (!found)
        throw RpcError(grpc::StatusCode::NOT_FOUND,
                       "map '" + req->map() + "' has no robot '" + req->robot() + "'" +
                           (req->session().empty() ? "" : " with session '" + req->session() + "'"));
    }
    const auto version = store.graphVersion(req->map());
    std::map<std::int64_t, storage::SessionFrame> frames;
    for (auto& f : store.sessionFrames(req->map())) frames[f.session_id] = f;
    std::int64_t last = 0;
    std::vector<storage::GraphNodeRecord> nodes;
    for (auto& n : store.graphNodes(req->map(), req->page_token())) {
      if (!n.odometry_pose) continue;
      if (!req->robot().empty() && n.robot != req->robot()) continue;
      if (!req->session().empty() && n.session != req->session()) continue;
      if (static_cast<std::int64_t>(nodes.size()) == page) {
        resp->set_next_page_token(last);
        break;
      }
      last = n.scan_id;
      nodes.push_back(std::move(n));
    }
    std::map<std::int64_t, Mat4d> optimised;
    if (!nodes.empty())
      for (const auto& p : store.optimisedPoses(req->map(), req->robot(), req->session(), req->page_token(), page))
        optimised[p.scan_id] = p.pose;
    for (const auto& n : nodes) {
      auto* o = resp->add_poses();
      o->set_scan_id(n.scan_id);
      o->set_robot(n.robot);
      o->set_session(n.session);
      o->set_seq(n.seq);
      if (n.stamp) o->set_stamp(*n.stamp);
      const auto f = frames.find(n.session_id);
      const bool connected = f != frames.end() && f->second.connected;
      o->set_connected(connected);
      if (const auto p = optimised.find(n.scan_id); p != optimised.end()) {
        o->set_optimised(true);
        wire::toTransform(p->second, o->mutable_t_map_scan());
      } else {
        // Not optimised yet: its odometry through the session's last known frame.
        wire::toTransform(f != frames.end() ? Mat4d(f->second.T_map_session * *n.odometry_pose) : *n.odometry_pose,
                          o->mutable_t_map_scan());
      }
    }
    resp->set_graph_version(version);
  });
}

grpc::Status PoseGraphService::GetSessionFrames(grpc::ServerContext* ctx, const v1::GetSessionFramesRequest* req,
                                                v1::GetSessionFramesResponse* resp) {
  return run(ctx, {"GetSessionFrames", req->map(), ""}, [&](CallLog&) {
    requireMap(state_, ctx, req->map());
    auto& store = state_.store();
    resp->set_graph_version(store.graphVersion(req->map()));
    std::map<std::pair<std::string, std::string>, storage::SessionFrame> frames;
    for (auto& f : store.sessionFrames(req->map())) frames[{f.robot, f.session}] = f;
    for (const auto& s : store.listSessions(req->map())) {
      auto* o = resp->add_sessions();
      o->set_robot(s.robot);
      o->set_session(s.name);
      const auto f = frames.find({s.robot, s.name});
      o->set_connected(f != frames.end() && f->second.connected);
      wire::toTransform(f != frames.end() ? f->second.T_map_session : Mat4d::Identity(), o->mutable_t_map_session());
    }
  });
}

grpc::Status PoseGraphService::ExportGraph(grpc::ServerContext* ctx, const v1::ExportGraphRequest* req,
                                           grpc::ServerWriter<v1::ExportChunk>* writer) {
  return run(ctx, {"ExportGraph", req->map(), ""}, [&](CallLog&) {
    requireMap(state_, ctx, req->map());
    const std::string format = req->format().empty() ? "g2o" : req->format();
    if (format != "g2o" && format != "json" && format != "mcap")
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "format must be g2o, json or mcap, not '" + format + "'");
    if (req->robots_size() > 1000)
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT,
                     "robots lists " + std::to_string(req->robots_size()) + " names; at most 1000");
    std::vector<std::string> robots(req->robots().begin(), req->robots().end());
    auto& store = state_.store();
    for (const auto& r : robots) {
      checkFilterName("robots[]", r);
      if (store.listSessions(req->map(), r).empty())
        throw RpcError(grpc::StatusCode::NOT_FOUND, "map '" + req->map() + "' has no robot '" + r + "'");
    }
    const auto* graph = state_.graph();
    if (!graph) throw RpcError(grpc::StatusCode::UNAVAILABLE, "the pose graph is loading or the server is stopping");
    const auto g = posegraph::exportGraph(store, req->map(), graph->options(), robots);
    std::vector<std::pair<std::string, std::ostringstream>> files;
    std::size_t keyframes = 0;
    if (format == "g2o") {
      files.emplace_back("graph.g2o", std::ostringstream());
      files.emplace_back("graph.ids.csv", std::ostringstream());
      files.emplace_back("graph.left_out.csv", std::ostringstream());
      posegraph::writeG2o(g, files[0].second, files[1].second);
      posegraph::writeLeftOutCsv(g, files[2].second);
    } else if (format == "json") {
      files.emplace_back("graph.json", std::ostringstream());
      posegraph::writeGraphJson(g, files[0].second);
    } else {
      files.emplace_back("graph.mcap", std::ostringstream());
      // Keyframe points where the map kept them (store_raw), read one scan at a time.
      keyframes = posegraph::writeGraphMcap(g, files[0].second, [&](std::int64_t scan_id) -> std::optional<Points> {
        checkAlive(ctx);
        auto raw = store.rawScan(scan_id);
        if (!raw) return std::nullopt;
        return std::move(raw->points);
      });
    }
    v1::ExportChunk chunk;
    auto* summary = chunk.mutable_summary();
    summary->set_nodes(static_cast<std::int64_t>(g.nodes.size()));
    const auto loops = std::count_if(g.edges.begin(), g.edges.end(), [](const auto& e) { return e.loop_id != 0; });
    summary->set_loop_edges(loops);
    summary->set_odometry_edges(static_cast<std::int64_t>(g.edges.size()) - loops);
    summary->set_loops_left_out(static_cast<std::int64_t>(g.left_out.size()));
    summary->set_graph_version(g.graph_version);
    summary->set_keyframes(static_cast<std::int64_t>(keyframes));
    constexpr std::size_t kChunk = 1 << 20;
    for (auto& [name, stream] : files) {
      const std::string data = stream.str();
      for (std::size_t at = 0; at == 0 || at < data.size(); at += kChunk) {
        chunk.set_file(name);
        chunk.set_data(data.substr(at, kChunk));
        if (ctx->IsCancelled() || !writer->Write(chunk))
          throw RpcError(grpc::StatusCode::CANCELLED, "export cancelled");
        chunk.Clear();
      }
    }
  });
}

grpc::Status PoseGraphService::GetLoops(grpc::ServerContext* ctx, const v1::GetLoopsRequest* req,
                                        v1::GetLoopsResponse* resp) {
  return run(ctx, {"GetLoops", req->map(), req->robot()}, [&](CallLog&) {
    requireMap(state_, ctx, req->map());
    checkFilterName("robot", req->robot());
    if (req->page_token() < 0) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "page_token must be >= 0");
    const std::int64_t page = pageSize(req->page_size());
    const auto& store = state_.store();
    if (!req->robot().empty() && store.listSessions(req->map(), req->robot()).empty())
      throw RpcError(grpc::StatusCode::NOT_FOUND, "map '" + req->map() + "' has no robot '" + req->robot() + "'");
    // Loops in chunks from the token on (each read bounded, so paging a large map is linear), their ends
    // looked up after the loop was read: a loop's ends are stored before it, so a missing end was deleted.
    LoopEnds ends(store);
    for (std::int64_t after = req->page_token();;) {
      const auto chunk = store.loops(req->map(), after, page + 1);
      for (const auto& l : chunk) {
        after = l.id;
        const auto* query = ends.find(l.query_scan);
        const auto* candidate = ends.find(l.candidate_scan);
        if (!query || !candidate) continue;
        if (!req->robot().empty() && query->robot() != req->robot() && candidate->robot() != req->robot()) continue;
        if (resp->loops_size() == page) {
          resp->set_next_page_token(resp->loops(page - 1).id());
          return;
        }
        toWire(l, *query, *candidate, resp->add_loops());
      }
      if (static_cast<std::int64_t>(chunk.size()) <= page) return;
    }
  });
}

}  // namespace sglc::server
