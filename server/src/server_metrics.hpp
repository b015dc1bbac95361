// What the server measures for Prometheus (`--metrics-listen`): every RPC by method and status code (count
// and duration), the engine's stage timings, scans stored by label source, loop candidates verified or refused
// by reason, pose-graph solve times, and, read at each scrape, the compute queue, scan bytes in flight, map and
// index sizes, each map's pose-graph loops accepted and rejected, and the process's memory.
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include <memory>
#include <string>

#include "metrics.hpp"
#include "sglc/closing/loop_query.hpp"
#include "sglc/posegraph/graph_optimiser.hpp"
#include "sglc/v1/sglc.pb.h"

namespace sglc::server {

class ServiceState;

// Metric names (also the documentation's list: docs/OPERATIONS.md).
inline constexpr const char* kRpcTotal = "sglc_rpc_requests_total";
inline constexpr const char* kRpcSeconds = "sglc_rpc_duration_seconds";
inline constexpr const char* kStageSeconds = "sglc_stage_duration_seconds";
inline constexpr const char* kSolveSeconds = "sglc_pose_graph_solve_seconds";
inline constexpr const char* kScansIngested = "sglc_scans_ingested_total";
inline constexpr const char* kLoopCandidates = "sglc_loop_candidates_total";

// A registry with the server's counter and histogram families declared (updated whether or not they are served).
std::unique_ptr<Metrics> newServerMetrics();
// Declares the gauges read from `state` at scrape time (when the metrics are served).
void declareServerGauges(Metrics& metrics, const ServiceState& state);
// Counts each call by method and final status code, and its duration (streams: their whole life).
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> makeMetricsInterceptorFactory(Metrics& metrics);
// The stage timings of one ingest or query (stages that did not run, with 0 ms, are not observed).
void observeStages(Metrics& metrics, const v1::Timing& timing);
// One pose-graph solve (result: converged, bounded or failed).
void observeSolve(Metrics& metrics, const posegraph::GraphEvent& event);
// A scan stored (not a retry of a stored one), by where its labels came from.
void countScan(Metrics& metrics, v1::LabelSource source);
// The candidates one ingest or query verified: verified, or refused by reason (a short name of the engine's
// reason: low_probability, no_pose, narrow_view, landmarks, translation).
void countCandidates(Metrics& metrics, const closing::QueryTiming& decided);

}  // namespace sglc::server
