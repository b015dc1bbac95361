#include "service.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <tuple>

#include "call.hpp"
#include "compaction_timer.hpp"
#include "query_codec.hpp"
#include "rpc_error.hpp"
#include "server_metrics.hpp"
#include "sglc/closing/ingestor.hpp"
#include "sglc/closing/loop_finder.hpp"
#include "sglc/closing/sweep_undo.hpp"
#include "sglc/config/engine_file.hpp"
#include "sglc/log/log_line.hpp"
#include "sglc/version.hpp"
#include "sglc/wire/geometry_codec.hpp"
#include "sglc/wire/scan_codec.hpp"
#include "sglc/wire/sweep_codec.hpp"
#include "viz_hub.hpp"

namespace sglc::server {
namespace {

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
        logging::logLine(
            {{"event", "scan_warning"}, {"map", map}, {"robot", robot}, {"seq", seq}, {"warnings", report.warnings}}));
}

// A scan that came with point times: whether it was de-skewed, and if not why (also in the log).
template <typename Response>
void reportSweep(const closing::SweepOutcome& sweep, const std::string& map, const std::string& robot, std::int64_t seq,
                 Response* resp) {
  resp->set_deskewed(sweep.deskewed);
  if (!sweep.warning) return;
  resp->add_warnings(*sweep.warning);
  spdlog::warn("{}", logging::logLine({{"event", "scan_warning"},
                                       {"map", map},
                                       {"robot", robot},
                                       {"seq", seq},
                                       {"warnings", std::vector<std::string>{*sweep.warning}}}));
}

// Engine work of a call: spread over the compute pool's idle threads, abandoned when the call is.
closing::Execution executionOf(const ServiceState& state, const grpc::ServerContextBase* ctx) {
  return {[&state](std::size_t n, const std::function<void(std::size_t)>& fn) { state.compute().parallelFor(n, fn); },
          [ctx] { checkAlive(ctx); }};
}

// The request's fields after the key's names and the caller's access are checked.
closing::IngestInput ingestInput(const v1::IngestRequest& req) {
  const auto& key = req.key();
  closing::IngestInput in;
  in.key = {key.map(), key.robot(), key.session(), key.seq()};
  if (req.has_stamp()) {
    if (!std::isfinite(req.stamp())) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "stamp is not finite");
    in.stamp = req.stamp();
  }
  if (req.has_odometry_pose() && req.odometry_pose().m_size() > 0)
    in.odometry_pose = wire::decodeRigidTransform(req.odometry_pose(), "odometry_pose");
  in.store_raw = req.store_raw();
  in.query = req.query();
  if (in.query) in.query_options = fromWire(req.query_options());
  return in;
}

}  // namespace

void ingestScan(const ServiceState& state, const grpc::ServerContextBase* ctx, const TokenTable::Grant& grant,
                const v1::IngestRequest& req, const std::string& points, const std::string& labels,
                const std::string& point_times, v1::IngestResponse* resp, MemoryBudget::Lease* held) {
  const auto t_start = Clock::now();
  const auto& key = req.key();
  wire::checkName("key.map", key.map());
  wire::checkName("key.robot", key.robot());
  wire::checkName("key.session", key.session());
  TokenTable::require(grant, key.map());
  auto input = ingestInput(req);
  const bool input_query = input.query;
  state.usableMap(key.map());
  auto& store = state.store();
  MemoryBudget::Lease own;
  if (!held)
    own = state.memory().acquire((points.size() + labels.size() + point_times.size()) * kScanCostFactor,
                                 ctx->deadline(), [ctx] { return ctx->IsCancelled(); });
  auto scan = wire::decodeScan(points, labels, state.limits().max_points);
  const auto sweep = wire::decodeSweep(point_times, req.scan().twist(), scan.points.size());
  checkAlive(ctx);
  reportSweep(closing::undoSweep(sweep, scan, &store, &input), key.map(), key.robot(), key.seq(), resp);

  auto* graph = state.graph();
  closing::Ingestor::LoopsRecorded recorded;
  if (graph) recorded = [graph](const std::string& map) { graph->loopsAdded(map); };
  const closing::Ingestor ingestor(state.pipeline(), store, std::move(recorded), state.limits().lifelong);
  // Engine work holds a compute slot; the database write does not.
  auto slot = state.compute().acquire(ctx);
  auto pending = ingestor.compute(scan, std::move(input), executionOf(state, ctx), [&](const ScanReport& report) {
    reportScan(report, key.map(), key.robot(), key.seq(), resp);
  });
  slot.release();
  checkAlive(ctx);  // past this point the scan is stored and the call succeeds
  const auto done = ingestor.commit(std::move(pending), scan);
  if (!done.already_stored) countScan(state.metrics(), resp->label_source());
  if (auto* viz = state.viz(); viz && !done.already_stored) viz->scanStored(key.map(), done.scan_id, scan.points);
  if (input_query) countCandidates(state.metrics(), done.timing.query);

  toWire(done.loops, resp->mutable_loops(), req.query_options().include_evidence());
  auto* timing = resp->mutable_timing();
  toWire(done.timing.query, timing);
  timing->set_fingerprint_ms(done.timing.fingerprint_ms);
  timing->set_store_ms(done.timing.store_ms);
  resp->set_scan_id(done.scan_id);
  resp->set_already_stored(done.already_stored);
  if (done.place) {
    resp->set_place_id(done.place->place_id);
    resp->set_kept(done.place->kept);
  } else if (state.limits().lifelong.enabled() && !done.already_stored) {
    spdlog::warn("{}", logging::logLine({{"event", "place_not_recorded"},
                                         {"scan", done.scan_id},
                                         {"error", done.report.warnings.empty() ? "" : done.report.warnings.back()}}));
  }
  for (const auto& error : done.unrecorded_loops)
    spdlog::warn("{}", logging::logLine({{"event", "loop_not_recorded"}, {"scan", done.scan_id}, {"error", error}}));
  resp->set_seq(key.seq());
  timing->set_total_ms(msSince(t_start));
  observeStages(state.metrics(), *timing);
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
    ingestScan(state_, ctx, grant, *req, req->scan().points(), req->scan().labels(), req->scan().point_times(), resp);
  });
}

grpc::Status LoopClosureService::Query(grpc::ServerContext* ctx, const v1::QueryRequest* req, v1::QueryResponse* resp) {
  return run(ctx, {"Query", req->map(), req->robot()}, [&](CallLog&) {
    const auto t_start = Clock::now();
    const auto grant = state_.tokens().authenticate(*ctx);
    wire::checkName("map", req->map());
    TokenTable::require(grant, req->map());
    state_.usableMap(req->map());
    auto& store = state_.store();
    const closing::LoopFinder finder(state_.pipeline(), store);
    closing::QueryOrigin who{req->map(), req->robot(), req->session(), req->seq(), std::nullopt, 0};
    if (req->has_stamp()) {
      if (!std::isfinite(req->stamp())) throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "stamp is not finite");
      who.stamp = req->stamp();
    }
    std::shared_ptr<const Fingerprint> fp;
    auto slot = state_.compute().acquire(ctx);
    if (req->has_scan()) {
      auto scan = wire::decodeScan(req->scan().points(), req->scan().labels(), state_.limits().max_points);
      const auto sweep = wire::decodeSweep(req->scan().point_times(), req->scan().twist(), scan.points.size());
      reportSweep(closing::undoSweep(sweep, scan), req->map(), req->robot(), req->seq(), resp);
      const auto t0 = Clock::now();
      ScanReport report;
      fp = std::make_shared<const Fingerprint>(state_.pipeline().fingerprint(scan, &report));
      reportScan(report, req->map(), req->robot(), req->seq(), resp);
      resp->mutable_timing()->set_fingerprint_ms(msSince(t0));
    } else if (req->has_scan_id()) {
      std::tie(fp, who) = finder.storedQuery(req->map(), req->scan_id());
    } else {
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "give either scan or scan_id");
    }
    closing::QueryTiming timing;
    const auto options = fromWire(req->options());
    toWire(finder.find(*fp, who, options, executionOf(state_, ctx), &timing), resp->mutable_candidates(),
           req->options().include_evidence());
    countCandidates(state_.metrics(), timing);
    toWire(timing, resp->mutable_timing());
    resp->mutable_timing()->set_total_ms(msSince(t_start));
    observeStages(state_.metrics(), resp->timing());
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
    checkFilterName("robot", req->robot());
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
    checkFilterName("robot", req->robot());
    checkFilterName("session", req->session());
    resp->set_scans_removed(state_.store().deleteSession(req->map(), req->robot(), req->session()));
    // The pose graph drops the removed scans and their loops and is solved again without them.
    if (auto* graph = state_.graph(); graph && resp->scans_removed() > 0) graph->scansRemoved(req->map());
  });
}

grpc::Status MapAdminService::DeleteRobot(grpc::ServerContext* ctx, const v1::DeleteRobotRequest* req,
                                          v1::DeleteResponse* resp) {
  return run(ctx, {"DeleteRobot", req->map(), req->robot()}, [&](CallLog&) {
    TokenTable::require(state_.tokens().authenticate(*ctx), req->map());
    checkFilterName("robot", req->robot());
    resp->set_scans_removed(state_.store().deleteRobot(req->map(), req->robot()));
    // The pose graph drops the removed scans and their loops and is solved again without them.
    if (auto* graph = state_.graph(); graph && resp->scans_removed() > 0) graph->scansRemoved(req->map());
  });
}

grpc::Status MapAdminService::DeleteMap(grpc::ServerContext* ctx, const v1::DeleteMapRequest* req,
                                        v1::DeleteResponse* resp) {
  return run(ctx, {"DeleteMap", req->map(), ""}, [&](CallLog&) {
    const auto map = requireMap(state_, ctx, req->map());
    resp->set_scans_removed(state_.store().deleteMap(req->map()));
    if (auto* graph = state_.graph()) graph->mapDeleted(req->map(), map.id);
    spdlog::info("{}",
                 logging::logLine({{"event", "map_deleted"}, {"map", req->map()}, {"scans", resp->scans_removed()}}));
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
    resp->set_places(s.places);
    resp->set_versions(s.versions);
    resp->set_retired_scans(s.retired_scans);
    resp->set_retired_bytes(s.retired_bytes);
    if (auto* graph = state_.graph(); graph && !req->map().empty())
      if (const auto event = graph->latest(req->map()); event && event->failed) {
        resp->set_pose_graph_failed(true);
        resp->set_pose_graph_error(event->error);
      }
  });
}

grpc::Status MapAdminService::Compact(grpc::ServerContext* ctx, const v1::CompactRequest* req,
                                      v1::CompactResponse* resp) {
  return run(ctx, {"Compact", req->map(), ""}, [&](CallLog&) {
    TokenTable::require(state_.tokens().authenticate(*ctx), req->map());
    requireMap(state_, ctx, req->map());
    const auto& policy = state_.limits().lifelong;
    const auto r =
        closing::compact(state_.store(), req->map(), policy, state_.limits().odometry,
                         std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count());
    // The pose graph drops the retired scans and solves again with their loops moved.
    if (auto* graph = state_.graph(); graph && r.retired > 0) graph->scansRemoved(req->map());
    resp->set_placed(r.placed);
    resp->set_promoted(r.promoted);
    resp->set_demoted(r.demoted);
    resp->set_retired(r.retired);
    resp->set_retired_bytes(r.retired_bytes);
    resp->set_loops_moved(r.loops_moved);
    resp->set_loops_dropped(r.loops_dropped);
    resp->set_open_sessions(r.open_sessions);
    resp->set_places(r.places);
    resp->set_versions(r.versions);
    resp->set_policy_on(policy.enabled());
    logCompaction(req->map(), r);
  });
}

grpc::Status MapAdminService::GetServerInfo(grpc::ServerContext* ctx, const v1::GetServerInfoRequest*,
                                            v1::GetServerInfoResponse* resp) {
  return run(ctx, {"GetServerInfo", "", ""}, [&](CallLog&) {
    state_.tokens().authenticate(*ctx);  // any valid token may ask
    const auto& config = state_.pipeline().config();
    const auto& labels = config.labels;
    resp->set_version(kVersion);
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
    resp->set_loop_model(state_.pipeline().model().version());
    resp->set_min_probability(config.verify.min_probability);
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
    if (ec) {
      using Code = storage::StorageError::Code;
      // A read-only file system (or no permission) is UNAVAILABLE, as for the database itself; a full one
      // RESOURCE_EXHAUSTED.
      const Code code = ec == std::errc::read_only_file_system || ec == std::errc::permission_denied ||
                                ec == std::errc::operation_not_permitted
                            ? Code::kReadOnly
                        : ec == std::errc::no_space_on_device ? Code::kFull
                                                              : Code::kIo;
      throw storage::StorageError(code, "the server's backup directory cannot be created",
                                  dir.string() + ": " + ec.message());
    }
    const auto dest = (dir / name).string();
    state_.store().backup(dest);
    resp->set_path(dest);
    resp->set_bytes(static_cast<std::int64_t>(fs::file_size(dest, ec)));
  });
}

}  // namespace sglc::server
