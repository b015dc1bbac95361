#include "service.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <optional>
#include <unordered_set>

#include "call.hpp"
#include "log_line.hpp"
#include "rpc_error.hpp"
#include "sglc/wire/geometry_codec.hpp"
#include "sglc/wire/scan_codec.hpp"

namespace sglc::server {
namespace {

// Who is asking and what they may see.
struct Asker {
  std::string map, robot, session;
  std::int64_t seq = 0;
  std::optional<double> stamp;
  std::int64_t self_scan = 0;  // a stored query scan never matches itself
};

void findLoops(const ServiceState& state, const grpc::ServerContextBase* ctx, const Fingerprint& query,
               const Asker& who, const v1::QueryOptions& opt, google::protobuf::RepeatedPtrField<v1::Candidate>* out,
               v1::Timing* timing) {
  const auto top_k = opt.top_k() ? opt.top_k() : 5u;
  if (top_k > 100) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "top_k must be at most 100");
  const auto candidates = opt.candidates() ? opt.candidates() : std::max(top_k, 10u);
  if (candidates > 200) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "candidates must be at most 200");
  if (opt.exclude_recent() < 0 || !std::isfinite(opt.exclude_seconds()) || opt.exclude_seconds() < 0)
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "exclude_recent and exclude_seconds must be >= 0");
  const bool refine = opt.refine_set() ? opt.refine() : true;
  if (opt.known_loops() && !refine)
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "known_loops asks for poses: it cannot go with refine = false");
  const bool include_rejected = opt.include_rejected() || opt.known_loops();
  if (opt.has_min_score() && !std::isfinite(opt.min_score()))
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "min_score is not finite");

  storage::SearchRequest req;
  req.map = who.map;
  req.descriptor = query.descriptor;
  req.k = static_cast<int>(candidates);
  req.self_robot = who.robot;
  req.self_session = who.session;
  req.self_seq = who.seq;
  req.exclude_recent = opt.exclude_recent();
  req.self_stamp = who.stamp;
  req.exclude_seconds = opt.exclude_seconds();
  if (who.self_scan) req.exclude_scan_ids.push_back(who.self_scan);
  switch (opt.scope()) {
    case v1::SCOPE_UNSPECIFIED:
    case v1::SCOPE_WHOLE_MAP:
      break;
    case v1::SCOPE_SAME_ROBOT:
    case v1::SCOPE_OTHER_ROBOTS:
      if (who.robot.empty())
        throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "scope SAME_ROBOT / OTHER_ROBOTS needs the query's robot");
      (opt.scope() == v1::SCOPE_SAME_ROBOT ? req.robots : req.exclude_robots).push_back(who.robot);
      break;
    case v1::SCOPE_SESSIONS:
      if (opt.sessions().empty() && opt.session_refs().empty())
        throw RpcError(grpc::StatusCode::INVALID_ARGUMENT,
                       "scope SESSIONS needs at least one 'robot/session' in sessions or one session_refs entry");
      for (const auto& s : opt.sessions()) {
        const auto slash = s.find('/');
        if (slash == std::string::npos)
          throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "sessions entry '" + s + "' is not 'robot/session'");
        req.session_refs.emplace_back(s.substr(0, slash), s.substr(slash + 1));
      }
      for (const auto& r : opt.session_refs()) req.session_refs.emplace_back(r.robot(), r.session());
      break;
    default:
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "unknown scope");
  }
  auto& store = state.store();
  auto t0 = Clock::now();
  std::vector<storage::SearchHit> hits;
  if (opt.verify_scan_ids_size() > 0) {
    if (opt.verify_scan_ids_size() > 200)
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "verify_scan_ids: at most 200");
    std::unordered_set<std::int64_t> seen;
    for (const auto id : opt.verify_scan_ids()) {
      if (!seen.insert(id).second)
        throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "verify_scan_ids repeats scan " + std::to_string(id));
      const auto info = store.scanInfo(id);
      const auto fp = info && info->map == who.map ? store.fingerprint(id) : nullptr;
      if (!fp) throw RpcError(grpc::StatusCode::NOT_FOUND, "map '" + who.map + "' has no scan " + std::to_string(id));
      if (fp->descriptor.size() != query.descriptor.size())
        throw RpcError(grpc::StatusCode::INVALID_ARGUMENT,
                       "scan " + std::to_string(id) + " has another descriptor layout");
      double d2 = 0;
      for (std::size_t i = 0; i < query.descriptor.size(); ++i)
        d2 += std::pow(double(query.descriptor[i]) - double(fp->descriptor[i]), 2);
      hits.push_back({id, static_cast<float>(std::sqrt(d2))});
    }
  } else {
    hits = store.search(req);
  }
  timing->set_search_ms(msSince(t0));

  struct Verified {
    storage::SearchHit hit;
    std::shared_ptr<const Fingerprint> fp;
    LoopResult result;
  };
  std::vector<Verified> results;
  t0 = Clock::now();
  // Candidates are verified independently (in parallel when compute threads are idle) and kept in search order.
  std::vector<std::optional<Verified>> verified(hits.size());
  state.compute().parallelFor(hits.size(), [&](std::size_t i) {
    checkAlive(ctx);
    auto fp = store.fingerprint(hits[i].scan_id);
    if (!fp) return;  // deleted meanwhile
    auto r = state.pipeline().verify(query, *fp);
    if (r.is_loop || include_rejected) verified[i] = Verified{hits[i], std::move(fp), std::move(r)};
  });
  for (auto& v : verified)
    if (v) results.push_back(std::move(*v));
  timing->set_verify_ms(msSince(t0));
  std::stable_sort(results.begin(), results.end(), [](const Verified& a, const Verified& b) {
    if (a.result.is_loop != b.result.is_loop) return a.result.is_loop;
    if (a.result.score != b.result.score) return a.result.score > b.result.score;
    return a.hit.scan_id < b.hit.scan_id;
  });
  if (opt.has_min_score())
    std::erase_if(results, [&](const Verified& v) { return v.result.is_loop && v.result.score < opt.min_score(); });
  if (results.size() > top_k) results.resize(top_k);
  t0 = Clock::now();
  if (refine)
    state.compute().parallelFor(results.size(), [&](std::size_t i) {
      checkAlive(ctx);
      state.pipeline().refine(query, *results[i].fp, results[i].result, opt.known_loops());
    });
  timing->set_refine_ms(msSince(t0));
  for (const auto& v : results) {
    auto* c = out->Add();
    c->set_scan_id(v.hit.scan_id);
    if (auto info = store.scanInfo(v.hit.scan_id)) {
      c->set_robot(info->robot);
      c->set_session(info->session);
      c->set_seq(info->seq);
    }
    c->set_score(v.result.score);
    c->set_verified(v.result.is_loop);
    c->set_inliers(v.result.inliers);
    c->set_fitness(v.result.fitness);
    c->set_rmse(v.result.rmse);
    c->set_refined(v.result.refined);
    if (v.result.refined && !v.result.information.isZero()) wire::encodeInformation(v.result.information, c);
    c->set_descriptor_distance(v.hit.distance);
    wire::toTransform(v.result.T, c->mutable_t_query_candidate());
  }
}

v1::LabelSource toWire(ScanReport::LabelSource source) {
  switch (source) {
    case ScanReport::LabelSource::kComputed:
      return v1::LABELS_COMPUTED;
    case ScanReport::LabelSource::kCompleted:
      return v1::LABELS_COMPLETED;
    default:
      return v1::LABELS_PROVIDED;
  }
}

// Where the scan's labels came from and what may keep it from closing loops: into the response, and warnings
// into the log too.
template <typename Response>
void reportScan(const ScanReport& report, const std::string& map, const std::string& robot, std::int64_t seq,
                Response* resp) {
  resp->set_label_source(toWire(report.label_source));
  for (const auto& w : report.warnings) resp->add_warnings(w);
  if (!report.warnings.empty())
    spdlog::warn(
        "{}",
        logLine(
            {{"event", "scan_warning"}, {"map", map}, {"robot", robot}, {"seq", seq}, {"warnings", report.warnings}}));
}

// Throws ALREADY_EXISTS unless the stored scan `id` is what this request would have stored (a retry).
void requireSameScan(const storage::MapStore& store, std::int64_t id, const Fingerprint& fp,
                     const v1::IngestRequest& req, const std::optional<Mat4d>& pose) {
  const auto& key = req.key();
  const auto info = store.scanInfo(id);
  const auto stored = store.fingerprint(id);
  const bool same = info && stored && serialize(*stored) == serialize(fp) &&
                    info->stamp == (req.has_stamp() ? std::optional<double>(req.stamp()) : std::nullopt) &&
                    info->odometry_pose.has_value() == pose.has_value() && (!pose || *info->odometry_pose == *pose) &&
                    info->has_raw == req.store_raw();
  if (!same)
    throw RpcError(grpc::StatusCode::ALREADY_EXISTS, "robot '" + key.robot() + "' session '" + key.session() +
                                                         "' seq " + std::to_string(key.seq()) +
                                                         " already holds a different scan (scan " + std::to_string(id) +
                                                         "); an identical retry would answer OK");
}

}  // namespace

void ingestScan(const ServiceState& state, const grpc::ServerContextBase* ctx, const TokenTable::Grant& grant,
                const v1::IngestRequest& req, const std::string& points, const std::string& labels,
                v1::IngestResponse* resp, MemoryBudget::Lease* held) {
  const auto t_start = Clock::now();
  const auto& key = req.key();
  wire::checkName("key.map", key.map());
  wire::checkName("key.robot", key.robot());
  wire::checkName("key.session", key.session());
  TokenTable::require(grant, key.map());
  if (req.has_stamp() && !std::isfinite(req.stamp()))
    throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "stamp is not finite");
  std::optional<Mat4d> pose;
  if (req.has_odometry_pose() && req.odometry_pose().m_size() > 0)
    pose = wire::decodeRigidTransform(req.odometry_pose(), "odometry_pose");
  auto& store = state.store();
  if (!store.findMap(key.map())) throw RpcError(grpc::StatusCode::NOT_FOUND, "no map named '" + key.map() + "'");
  MemoryBudget::Lease own;
  if (!held)
    own = state.memory().acquire((points.size() + labels.size()) * kScanCostFactor, ctx->deadline(),
                                 [ctx] { return ctx->IsCancelled(); });
  const auto scan = wire::decodeScan(points, labels, state.limits().max_points);
  checkAlive(ctx);

  // Engine work holds a compute slot; the database write below does not.
  auto slot = state.compute().acquire(ctx);
  auto t0 = Clock::now();
  ScanReport report;
  const auto fp = state.pipeline().fingerprint(scan, &report);
  resp->mutable_timing()->set_fingerprint_ms(msSince(t0));
  reportScan(report, key.map(), key.robot(), key.seq(), resp);
  // A retry of a stored scan answers as the first call did (its loops exclude the stored copy of itself).
  auto stored = store.findScan(key.map(), key.robot(), key.session(), key.seq());
  if (stored) requireSameScan(store, *stored, fp, req, pose);
  if (req.query()) {
    Asker who{key.map(), key.robot(), key.session(), key.seq(), std::nullopt, stored.value_or(0)};
    if (req.has_stamp()) who.stamp = req.stamp();
    findLoops(state, ctx, fp, who, req.query_options(), resp->mutable_loops(), resp->mutable_timing());
  }
  slot.release();
  checkAlive(ctx);  // past this point the scan is stored and the call succeeds
  t0 = Clock::now();
  if (!stored) {
    storage::NewScan ns;
    ns.map = key.map();
    ns.robot = key.robot();
    ns.session = key.session();
    ns.seq = key.seq();
    if (req.has_stamp()) ns.stamp = req.stamp();
    ns.odometry_pose = pose;
    ns.fingerprint = &fp;
    ns.raw = req.store_raw() ? &scan : nullptr;
    try {
      resp->set_scan_id(store.addScan(ns));
    } catch (const storage::StorageError& e) {
      // The same request on another connection (a client retrying before its first call answered) may have
      // stored it first.
      if (e.code() != storage::StorageError::Code::kAlreadyExists) throw;
      stored = store.findScan(key.map(), key.robot(), key.session(), key.seq());
      if (!stored) throw;
      requireSameScan(store, *stored, fp, req, pose);
      auto* loops = resp->mutable_loops();
      for (int i = loops->size() - 1; i >= 0; --i)
        if (loops->Get(i).scan_id() == *stored) loops->DeleteSubrange(i, 1);
    }
  }
  if (stored) {
    resp->set_scan_id(*stored);
    resp->set_already_stored(true);
  }
  resp->mutable_timing()->set_store_ms(msSince(t0));
  // Verified loops join the map's pose graph (the scan is stored: a failure here must not fail the call; a
  // loop recorded again for the same pair replaces the first).
  if (auto* graph = state.graph(); graph && pose) {
    bool added = false;
    for (const auto& loop : resp->loops()) {
      if (!loop.verified()) continue;
      try {
        // The engine's own pose (the rigid check guards what clients send; a loop it fails is only logged).
        storage::LoopRecord r;
        r.query_scan = resp->scan_id();
        r.candidate_scan = loop.scan_id();
        r.T = wire::decodeRigidTransform(loop.t_query_candidate(), "loop");
        r.score = loop.score();
        r.inliers = loop.inliers();
        r.fitness = loop.fitness();
        r.rmse = loop.rmse();
        r.information = wire::decodeInformation(loop);
        state.store().addLoop(key.map(), r);
        added = true;
      } catch (const std::exception& e) {
        spdlog::warn("{}", logLine({{"event", "loop_not_recorded"}, {"scan", resp->scan_id()}, {"error", e.what()}}));
      }
    }
    if (added) graph->loopsAdded(key.map());
  }
  resp->set_seq(key.seq());
  resp->mutable_timing()->set_total_ms(msSince(t_start));
}

storage::MapStore& ServiceState::store() const {
  auto* s = store_.load();
  if (!s) throw RpcError(grpc::StatusCode::UNAVAILABLE, "the map database is loading or the server is shutting down");
  return *s;
}

// ------------------------------------------------------------------------------------------------ LoopClosure

grpc::Status LoopClosureService::Ingest(grpc::ServerContext* ctx, const v1::IngestRequest* req,
                                        v1::IngestResponse* resp) {
  return run(ctx, {"Ingest", req->key().map(), req->key().robot()}, [&](CallLog&) {
    const auto grant = state_.tokens().authenticate(*ctx);
    ingestScan(state_, ctx, grant, *req, req->scan().points(), req->scan().labels(), resp);
  });
}

grpc::Status LoopClosureService::Query(grpc::ServerContext* ctx, const v1::QueryRequest* req, v1::QueryResponse* resp) {
  return run(ctx, {"Query", req->map(), req->robot()}, [&](CallLog&) {
    const auto t_start = Clock::now();
    const auto grant = state_.tokens().authenticate(*ctx);
    wire::checkName("map", req->map());
    TokenTable::require(grant, req->map());
    auto& store = state_.store();
    if (!store.findMap(req->map())) throw RpcError(grpc::StatusCode::NOT_FOUND, "no map named '" + req->map() + "'");
    Asker who{req->map(), req->robot(), req->session(), req->seq(), std::nullopt, 0};
    if (req->has_stamp()) who.stamp = req->stamp();
    std::shared_ptr<const Fingerprint> fp;
    auto slot = state_.compute().acquire(ctx);
    if (req->has_scan()) {
      const auto scan = wire::decodeScan(req->scan().points(), req->scan().labels(), state_.limits().max_points);
      const auto t0 = Clock::now();
      ScanReport report;
      fp = std::make_shared<const Fingerprint>(state_.pipeline().fingerprint(scan, &report));
      reportScan(report, req->map(), req->robot(), req->seq(), resp);
      resp->mutable_timing()->set_fingerprint_ms(msSince(t0));
    } else if (req->has_scan_id()) {
      const auto info = store.scanInfo(req->scan_id());
      if (!info || info->map != req->map())
        throw RpcError(grpc::StatusCode::NOT_FOUND,
                       "map '" + req->map() + "' has no scan " + std::to_string(req->scan_id()));
      fp = store.fingerprint(req->scan_id());
      if (!fp) throw RpcError(grpc::StatusCode::NOT_FOUND, "scan " + std::to_string(req->scan_id()) + " was deleted");
      who = {req->map(), info->robot, info->session, info->seq, info->stamp, req->scan_id()};
    } else {
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "give either scan or scan_id");
    }
    findLoops(state_, ctx, *fp, who, req->options(), resp->mutable_candidates(), resp->mutable_timing());
    resp->mutable_timing()->set_total_ms(msSince(t_start));
  });
}

// ------------------------------------------------------------------------------------------------ MapAdmin

namespace {
// The scan descriptor's length under this server's engine configuration (what its maps are created with).
int scanDescriptorDim(const Config& config) {
  return descriptorLayout(static_cast<int>(config.labels.node_classes.size()), config.graph, config.descriptor)
      .scanDim();
}

void fillMap(const storage::MapInfo& m, v1::MapInfo* out) {
  out->set_name(m.name);
  out->set_scans(m.scans);
  out->set_robots(m.robots);
  out->set_sessions(m.sessions);
  out->set_descriptor_dim(m.descriptor_dim);
}
}  // namespace

grpc::Status MapAdminService::CreateMap(grpc::ServerContext* ctx, const v1::CreateMapRequest* req, v1::MapInfo* resp) {
  return run(ctx, {"CreateMap", req->name(), ""}, [&](CallLog&) {
    const auto grant = state_.tokens().authenticate(*ctx);
    wire::checkName("name", req->name());
    TokenTable::require(grant, req->name());
    fillMap(state_.store().createMap(req->name(), scanDescriptorDim(state_.pipeline().config())), resp);
  });
}

grpc::Status MapAdminService::ListMaps(grpc::ServerContext* ctx, const v1::ListMapsRequest*,
                                       v1::ListMapsResponse* resp) {
  return run(ctx, {"ListMaps", "", ""}, [&](CallLog&) {
    // UNAVAILABLE while loading comes before authentication: clients probe readiness with ListMaps.
    auto& store = state_.store();
    const auto grant = state_.tokens().authenticate(*ctx);
    for (const auto& m : store.listMaps())
      if (grant.allows(m.name)) fillMap(m, resp->add_maps());
  });
}

grpc::Status MapAdminService::ListRobots(grpc::ServerContext* ctx, const v1::ListRobotsRequest* req,
                                         v1::ListRobotsResponse* resp) {
  return run(ctx, {"ListRobots", req->map(), ""}, [&](CallLog&) {
    TokenTable::require(state_.tokens().authenticate(*ctx), req->map());
    for (const auto& r : state_.store().listRobots(req->map())) {
      auto* o = resp->add_robots();
      o->set_name(r.name);
      o->set_scans(r.scans);
      o->set_sessions(r.sessions);
    }
  });
}

grpc::Status MapAdminService::ListSessions(grpc::ServerContext* ctx, const v1::ListSessionsRequest* req,
                                           v1::ListSessionsResponse* resp) {
  return run(ctx, {"ListSessions", req->map(), req->robot()}, [&](CallLog&) {
    TokenTable::require(state_.tokens().authenticate(*ctx), req->map());
    for (const auto& s : state_.store().listSessions(req->map(), req->robot())) {
      auto* o = resp->add_sessions();
      o->set_robot(s.robot);
      o->set_name(s.name);
      o->set_scans(s.scans);
      o->set_first_seq(s.first_seq);
      o->set_last_seq(s.last_seq);
    }
  });
}

grpc::Status MapAdminService::GetScan(grpc::ServerContext* ctx, const v1::GetScanRequest* req,
                                      v1::GetScanResponse* resp) {
  return run(ctx, {"GetScan", "", ""}, [&](CallLog& log) {
    const auto grant = state_.tokens().authenticate(*ctx);
    auto& store = state_.store();
    const auto info = store.scanInfo(req->scan_id());
    // A scan of a map the token does not cover is answered as a missing one: probing ids must not reveal which
    // ids exist or what other maps are called.
    if (!info || !grant.allows(info->map))
      throw RpcError(grpc::StatusCode::NOT_FOUND, "no scan " + std::to_string(req->scan_id()));
    log.map = info->map;
    log.robot = info->robot;
    resp->set_scan_id(info->id);
    auto* key = resp->mutable_key();
    key->set_map(info->map);
    key->set_robot(info->robot);
    key->set_session(info->session);
    key->set_seq(info->seq);
    if (info->stamp) resp->set_stamp(*info->stamp);
    if (info->odometry_pose) wire::toTransform(*info->odometry_pose, resp->mutable_odometry_pose());
    resp->set_fingerprint_bytes(info->fingerprint_bytes);
    resp->set_has_raw(info->has_raw);
    if (req->include_graph()) {
      const auto fp = store.fingerprint(info->id);
      if (!fp) throw RpcError(grpc::StatusCode::NOT_FOUND, "scan was deleted");
      const auto& classes = state_.pipeline().config().labels.node_classes;
      for (const auto& n : fp->nodes) {
        auto* o = resp->add_nodes();
        o->set_x(n.center.x());
        o->set_y(n.center.y());
        o->set_z(n.center.z());
        o->set_length(n.size.x());
        o->set_width(n.size.y());
        o->set_height(n.size.z());
        o->set_cls(n.cls < classes.size() ? classes[n.cls].name : std::to_string(n.cls));
      }
      for (float v : fp->descriptor) resp->add_scan_descriptor(v);
    }
  });
}

grpc::Status MapAdminService::DeleteSession(grpc::ServerContext* ctx, const v1::DeleteSessionRequest* req,
                                            v1::DeleteResponse* resp) {
  return run(ctx, {"DeleteSession", req->map(), req->robot()}, [&](CallLog&) {
    TokenTable::require(state_.tokens().authenticate(*ctx), req->map());
    resp->set_scans_removed(state_.store().deleteSession(req->map(), req->robot(), req->session()));
    // The pose graph drops the removed scans and their loops and is solved again without them.
    if (auto* graph = state_.graph(); graph && resp->scans_removed() > 0) graph->scansRemoved(req->map());
  });
}

grpc::Status MapAdminService::DeleteRobot(grpc::ServerContext* ctx, const v1::DeleteRobotRequest* req,
                                          v1::DeleteResponse* resp) {
  return run(ctx, {"DeleteRobot", req->map(), req->robot()}, [&](CallLog&) {
    TokenTable::require(state_.tokens().authenticate(*ctx), req->map());
    resp->set_scans_removed(state_.store().deleteRobot(req->map(), req->robot()));
    // The pose graph drops the removed scans and their loops and is solved again without them.
    if (auto* graph = state_.graph(); graph && resp->scans_removed() > 0) graph->scansRemoved(req->map());
  });
}

grpc::Status MapAdminService::GetStats(grpc::ServerContext* ctx, const v1::GetStatsRequest* req,
                                       v1::GetStatsResponse* resp) {
  return run(ctx, {"GetStats", req->map(), ""}, [&](CallLog&) {
    TokenTable::require(state_.tokens().authenticate(*ctx), req->map());
    const auto s = state_.store().stats(req->map());
    resp->set_maps(s.maps);
    resp->set_robots(s.robots);
    resp->set_sessions(s.sessions);
    resp->set_scans(s.scans);
    resp->set_index_entries(s.index_entries);
    resp->set_db_bytes(s.db_bytes);
    resp->set_fingerprint_bytes(s.fingerprint_bytes);
    resp->set_cache_mb(s.cache_mb);
    if (auto* graph = state_.graph(); graph && !req->map().empty())
      if (const auto event = graph->latest(req->map()); event && event->failed) {
        resp->set_pose_graph_failed(true);
        resp->set_pose_graph_error(event->error);
      }
  });
}

grpc::Status MapAdminService::GetServerInfo(grpc::ServerContext* ctx, const v1::GetServerInfoRequest*,
                                            v1::GetServerInfoResponse* resp) {
  return run(ctx, {"GetServerInfo", "", ""}, [&](CallLog&) {
    state_.tokens().authenticate(*ctx);  // any valid token may ask
    const auto& config = state_.pipeline().config();
    const auto& labels = config.labels;
    resp->set_version(SGLC_VERSION);
    resp->set_label_preset(labels.preset);
    for (const auto& c : labels.node_classes) {
      auto* o = resp->add_node_classes();
      o->set_name(c.name);
      for (auto id : c.ids) o->add_ids(id);
    }
    for (auto id : labels.road) resp->add_road(id);
    for (auto id : labels.building) resp->add_building(id);
    for (auto id : labels.fence) resp->add_fence(id);
    for (auto id : labels.vegetation) resp->add_vegetation(id);
    for (auto id : labels.moving) resp->add_moving(id);
    resp->set_labeller_mode(config.labeller.mode);
    resp->set_engine_config(dumpConfig(config));
    resp->set_descriptor_dim(scanDescriptorDim(config));
    const auto& limits = state_.limits();
    resp->set_max_points(static_cast<std::int64_t>(limits.max_points));
    resp->set_max_message_bytes(limits.max_message_bytes);
    resp->set_max_streams_per_client(limits.streams.max_per_client);
    resp->set_stream_idle_timeout_s(std::chrono::duration<double>(limits.streams.idle_timeout).count());
    resp->set_max_inflight_bytes(static_cast<std::int64_t>(limits.max_inflight_bytes));
  });
}

grpc::Status MapAdminService::Backup(grpc::ServerContext* ctx, const v1::BackupRequest* req, v1::BackupResponse* resp) {
  return run(ctx, {"Backup", "", ""}, [&](CallLog&) {
    TokenTable::require(state_.tokens().authenticate(*ctx), "");
    namespace fs = std::filesystem;
    const std::string& path = req->path();
    const bool control = std::any_of(path.begin(), path.end(), [](unsigned char c) { return c < 0x20 || c == 0x7f; });
    if (path.empty() || path.size() > 255 || control || path.find('/') != std::string::npos || path == "." ||
        path == "..")
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT,
                     "backup path must be a plain file name (1..255 bytes, no '/', no control characters, not . or "
                     "..); it is written into the server's backup directory");
    const fs::path name(path);
    const auto dir = fs::path(state_.limits().backup_dir);
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec)
      throw storage::StorageError(storage::StorageError::Code::kIo, "the server's backup directory cannot be created",
                                  dir.string() + ": " + ec.message());
    const auto dest = (dir / name).string();
    state_.store().backup(dest);
    resp->set_path(dest);
    resp->set_bytes(static_cast<std::int64_t>(fs::file_size(dest, ec)));
  });
}

}  // namespace sglc::server

// ------------------------------------------------------------------------------------------------ PoseGraph

namespace sglc::server {
namespace {}  // namespace

void requireMap(const ServiceState& state, const grpc::ServerContextBase* ctx, const std::string& map) {
  wire::checkName("map", map);
  TokenTable::require(state.tokens().authenticate(*ctx), map);
  if (!state.store().findMap(map)) throw RpcError(grpc::StatusCode::NOT_FOUND, "no map named '" + map + "'");
}

grpc::Status PoseGraphService::GetPoses(grpc::ServerContext* ctx, const v1::GetPosesRequest* req,
                                        v1::GetPosesResponse* resp) {
  return run(ctx, {"GetPoses", req->map(), req->robot()}, [&](CallLog&) {
    requireMap(state_, ctx, req->map());
    if (!req->session().empty() && req->robot().empty())
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "a session needs its robot");
    if (req->page_token() < 0) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "page_token must be >= 0");
    const std::int64_t page = req->page_size() ? req->page_size() : 1000;
    if (page > 10000) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "page_size must be at most 10000");
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

}  // namespace sglc::server
