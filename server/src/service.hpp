// The sglc.v1 services: RPCs mapped onto the engine (core) and the map database (storage).
#pragma once

#include <atomic>
#include <filesystem>
#include <memory>
#include <string>

#include "auth.hpp"
#include "compute_pool.hpp"
#include "executor.hpp"
#include "map_settings_guard.hpp"
#include "memory_budget.hpp"
#include "server_metrics.hpp"
#include "sglc/closing/compaction.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/storage/map_store.hpp"
#include "sglc/types.hpp"
#include "sglc/v1/sglc.grpc.pb.h"
#include "stream_registry.hpp"

namespace sglc::server {

using posegraph::GraphEvent;
using posegraph::GraphOptimiser;
using posegraph::GraphOptimiserOptions;

struct ServiceLimits {
  std::size_t max_points = kMaxScanPoints;                // per scan
  std::string backup_dir;                                 // Backup paths are resolved inside it
  int compute_threads = 1;                                // engine work runs on at most this many threads at once
  std::size_t max_inflight_bytes = std::size_t{1} << 30;  // scan memory in flight (MemoryBudget)
  std::int64_t max_message_bytes = 64 << 20;
  StreamLimits streams;
  closing::LifelongOptions lifelong;  // the map section: places and versions (docs/LIFELONG.md)
  closing::OdometryNoise odometry;    // the pose graph's, for loops moved off retired scans
};

// State shared by both services. The store is attached once it is loaded; until then calls get UNAVAILABLE.
class VizHub;

class ServiceState {
 public:
  ServiceState(Pipeline pipeline, TokenTable tokens, ServiceLimits limits)
      : pipeline_(std::move(pipeline)),
        tokens_(std::move(tokens)),
        limits_(std::move(limits)),
        guard_(fingerprintSettings(pipeline_.config())),
        compute_(std::make_unique<ComputePool>(limits_.compute_threads)),
        memory_(std::make_unique<MemoryBudget>(limits_.max_inflight_bytes)),
        executor_(std::make_unique<Executor>(limits_.compute_threads + 2)),
        streams_(std::make_unique<StreamRegistry>(limits_.streams, [m = memory_.get()] { m->trim(); })) {}

  void attach(storage::MapStore* store, GraphOptimiser* graph = nullptr) {
    graph_.store(graph);
    store_.store(store);
  }
  void detach() {
    store_.store(nullptr);
    graph_.store(nullptr);
  }
  // The live view's hub (sglc-server --viz-listen), told of every stored scan; null: none.
  void attachViz(VizHub* viz) { viz_.store(viz); }
  storage::MapStore& store() const;  // throws RpcError(UNAVAILABLE) while loading
  // The map, when this server's fingerprints may be added to it and compared with its own (MapSettingsGuard):
  // every ingest and query asks here. NOT_FOUND, FAILED_PRECONDITION, or UNAVAILABLE while loading.
  storage::MapInfo usableMap(const std::string& map) const { return guard_.require(store(), map); }
  const MapSettingsGuard& settingsGuard() const { return guard_; }

  const Pipeline& pipeline() const { return pipeline_; }
  const TokenTable& tokens() const { return tokens_; }
  const ServiceLimits& limits() const { return limits_; }
  ComputePool& compute() const { return *compute_; }
  MemoryBudget& memory() const { return *memory_; }
  Executor& executor() const { return *executor_; }
  StreamRegistry& streams() const { return *streams_; }
  Metrics& metrics() const { return *metrics_; }           // served with --metrics-listen
  GraphOptimiser* graph() const { return graph_.load(); }  // null: no pose graph (tests, loading)
  VizHub* viz() const { return viz_.load(); }

 private:
  Pipeline pipeline_;
  TokenTable tokens_;
  ServiceLimits limits_;
  MapSettingsGuard guard_;
  std::unique_ptr<ComputePool> compute_;
  std::unique_ptr<MemoryBudget> memory_;
  std::unique_ptr<Executor> executor_;
  std::unique_ptr<StreamRegistry> streams_;
  std::unique_ptr<Metrics> metrics_ = newServerMetrics();
  std::atomic<storage::MapStore*> store_{nullptr};
  std::atomic<GraphOptimiser*> graph_{nullptr};
  std::atomic<VizHub*> viz_{nullptr};
};

// Unary methods run on gRPC's sync thread pool; the streams are callback reactors on raw bytes (streams.cpp)
// that hold no thread while they wait for their client and parse each message themselves, so one that is not
// valid protobuf fails the call with INVALID_ARGUMENT instead of passing for the client's half-close. A unary
// request that does not parse is answered INVALID_ARGUMENT by the interceptor in call.hpp.
using LoopClosureBase = v1::LoopClosure::WithRawCallbackMethod_IngestChunked<
    v1::LoopClosure::WithRawCallbackMethod_IngestStream<v1::LoopClosure::Service>>;

class LoopClosureService final : public LoopClosureBase {
 public:
  explicit LoopClosureService(ServiceState& state) : state_(state) {}
  grpc::Status Ingest(grpc::ServerContext* ctx, const v1::IngestRequest* req, v1::IngestResponse* resp) override;
  grpc::Status Query(grpc::ServerContext* ctx, const v1::QueryRequest* req, v1::QueryResponse* resp) override;
  grpc::ServerReadReactor<grpc::ByteBuffer>* IngestChunked(grpc::CallbackServerContext* ctx,
                                                           grpc::ByteBuffer* resp) override;
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* IngestStream(grpc::CallbackServerContext* ctx) override;

 private:
  ServiceState& state_;
};

class MapAdminService final : public v1::MapAdmin::Service {
 public:
  explicit MapAdminService(ServiceState& state) : state_(state) {}
  grpc::Status CreateMap(grpc::ServerContext* ctx, const v1::CreateMapRequest* req, v1::MapInfo* resp) override;
  grpc::Status ListMaps(grpc::ServerContext* ctx, const v1::ListMapsRequest* req, v1::ListMapsResponse* resp) override;
  grpc::Status ListRobots(grpc::ServerContext* ctx, const v1::ListRobotsRequest* req,
                          v1::ListRobotsResponse* resp) override;
  grpc::Status ListSessions(grpc::ServerContext* ctx, const v1::ListSessionsRequest* req,
                            v1::ListSessionsResponse* resp) override;
  grpc::Status GetScan(grpc::ServerContext* ctx, const v1::GetScanRequest* req, v1::GetScanResponse* resp) override;
  grpc::Status DeleteSession(grpc::ServerContext* ctx, const v1::DeleteSessionRequest* req,
                             v1::DeleteResponse* resp) override;
  grpc::Status DeleteRobot(grpc::ServerContext* ctx, const v1::DeleteRobotRequest* req,
                           v1::DeleteResponse* resp) override;
  grpc::Status DeleteMap(grpc::ServerContext* ctx, const v1::DeleteMapRequest* req, v1::DeleteResponse* resp) override;
  grpc::Status GetStats(grpc::ServerContext* ctx, const v1::GetStatsRequest* req, v1::GetStatsResponse* resp) override;
  grpc::Status GetServerInfo(grpc::ServerContext* ctx, const v1::GetServerInfoRequest* req,
                             v1::GetServerInfoResponse* resp) override;
  grpc::Status Backup(grpc::ServerContext* ctx, const v1::BackupRequest* req, v1::BackupResponse* resp) override;
  grpc::Status Compact(grpc::ServerContext* ctx, const v1::CompactRequest* req, v1::CompactResponse* resp) override;

 private:
  ServiceState& state_;
};

using PoseGraphBase = v1::PoseGraph::WithRawCallbackMethod_WatchMap<v1::PoseGraph::Service>;

class PoseGraphService final : public PoseGraphBase {
 public:
  explicit PoseGraphService(ServiceState& state) : state_(state) {}
  grpc::Status GetPoses(grpc::ServerContext* ctx, const v1::GetPosesRequest* req, v1::GetPosesResponse* resp) override;
  grpc::Status GetSessionFrames(grpc::ServerContext* ctx, const v1::GetSessionFramesRequest* req,
                                v1::GetSessionFramesResponse* resp) override;
  grpc::Status GetLoops(grpc::ServerContext* ctx, const v1::GetLoopsRequest* req, v1::GetLoopsResponse* resp) override;
  grpc::ServerWriteReactor<grpc::ByteBuffer>* WatchMap(grpc::CallbackServerContext* ctx,
                                                       const grpc::ByteBuffer* req) override;
  grpc::Status ExportGraph(grpc::ServerContext* ctx, const v1::ExportGraphRequest* req,
                           grpc::ServerWriter<v1::ExportChunk>* writer) override;

 private:
  ServiceState& state_;
};

// The shared body of the three ingest RPCs: validates, fingerprints, optionally queries, stores (idempotently:
// the identical scan re-sent for a stored key answers as the first time did). `held` is the caller's
// reservation of scan memory (chunked uploads reserve as chunks arrive); without one the call reserves its own.
void ingestScan(const ServiceState& state, const grpc::ServerContextBase* ctx, const TokenTable::Grant& grant,
                const v1::IngestRequest& req, const std::string& points, const std::string& labels,
                const std::string& point_times, v1::IngestResponse* resp, MemoryBudget::Lease* held = nullptr);
// Checks the map name and the caller's access, and that the map exists (NOT_FOUND); returns the map.
storage::MapInfo requireMap(const ServiceState& state, const grpc::ServerContextBase* ctx, const std::string& map);
// A robot or session name given as a filter: empty, or a valid name (INVALID_ARGUMENT otherwise, before it is
// echoed in any message).
void checkFilterName(const std::string& what, const std::string& name);

}  // namespace sglc::server
