// The sglc.v1 services: RPCs mapped onto the engine (core) and the map database (storage).
#pragma once

#include <atomic>
#include <filesystem>
#include <memory>
#include <string>

#include "auth.hpp"
#include "compute_pool.hpp"
#include "graph_optimiser.hpp"
#include "sglc/pipeline.hpp"
#include "sglc/storage/map_store.hpp"
#include "sglc/v1/sglc.grpc.pb.h"

namespace sglc::server {

struct ServiceLimits {
  std::size_t max_points = 2'000'000;      // per scan
  std::string backup_dir;                  // Backup paths are resolved inside it
  int compute_threads = 1;                 // engine work runs on at most this many threads at once
};

// State shared by both services. The store is attached once it is loaded; until then calls get UNAVAILABLE.
class ServiceState {
 public:
  ServiceState(Pipeline pipeline, TokenTable tokens, ServiceLimits limits)
      : pipeline_(std::move(pipeline)),
        tokens_(std::move(tokens)),
        limits_(std::move(limits)),
        compute_(std::make_unique<ComputePool>(limits_.compute_threads)) {}

  void attach(storage::MapStore* store, GraphOptimiser* graph = nullptr) {
    graph_.store(graph);
    store_.store(store);
  }
  void detach() {
    store_.store(nullptr);
    graph_.store(nullptr);
  }
  storage::MapStore& store() const;  // throws RpcError(UNAVAILABLE) while loading

  const Pipeline& pipeline() const { return pipeline_; }
  const TokenTable& tokens() const { return tokens_; }
  const ServiceLimits& limits() const { return limits_; }
  ComputePool& compute() const { return *compute_; }
  GraphOptimiser* graph() const { return graph_.load(); }  // null: no pose graph (tests, loading)

 private:
  Pipeline pipeline_;
  TokenTable tokens_;
  ServiceLimits limits_;
  std::unique_ptr<ComputePool> compute_;
  std::atomic<storage::MapStore*> store_{nullptr};
  std::atomic<GraphOptimiser*> graph_{nullptr};
};

class LoopClosureService final : public v1::LoopClosure::Service {
 public:
  explicit LoopClosureService(ServiceState& state) : state_(state) {}
  grpc::Status Ingest(grpc::ServerContext* ctx, const v1::IngestRequest* req, v1::IngestResponse* resp) override;
  grpc::Status IngestChunked(grpc::ServerContext* ctx, grpc::ServerReader<v1::IngestChunk>* reader,
                             v1::IngestResponse* resp) override;
  grpc::Status IngestStream(grpc::ServerContext* ctx,
                            grpc::ServerReaderWriter<v1::IngestResponse, v1::IngestRequest>* stream) override;
  grpc::Status Query(grpc::ServerContext* ctx, const v1::QueryRequest* req, v1::QueryResponse* resp) override;

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
  grpc::Status GetStats(grpc::ServerContext* ctx, const v1::GetStatsRequest* req, v1::GetStatsResponse* resp) override;
  grpc::Status Backup(grpc::ServerContext* ctx, const v1::BackupRequest* req, v1::BackupResponse* resp) override;

 private:
  ServiceState& state_;
};

class PoseGraphService final : public v1::PoseGraph::Service {
 public:
  explicit PoseGraphService(ServiceState& state) : state_(state) {}
  grpc::Status GetPoses(grpc::ServerContext* ctx, const v1::GetPosesRequest* req, v1::GetPosesResponse* resp) override;
  grpc::Status GetSessionFrames(grpc::ServerContext* ctx, const v1::GetSessionFramesRequest* req,
                                v1::GetSessionFramesResponse* resp) override;
  grpc::Status WatchMap(grpc::ServerContext* ctx, const v1::WatchMapRequest* req,
                        grpc::ServerWriter<v1::MapEvent>* writer) override;

 private:
  ServiceState& state_;
};

}  // namespace sglc::server
