// C++ client of the SGLC loop-closure service (the gRPC services of proto/sglc/v1/sglc.proto:
// LoopClosure, MapAdmin and PoseGraph; WatchMap is not wrapped: use the stub on channel()).
//
//   auto client = sglc::client::Client::connect("127.0.0.1:50051", {.token = "secret"});
//   client.createMap("campus");
//   auto r = client.ingest(sglc::client::makeKey("campus", "robot1", "run1", 42), scan);
//   auto loops = client.queryScanId("campus", r.scan_id()).candidates();
//
// Every call takes a deadline (CallOptions; the default comes from ConnectOptions). A call that fails on
// the server or on the way throws RpcError, which carries the gRPC status code and message. Input the
// client can reject before sending (e.g. a scan whose point and label counts differ) throws
// sglc::InputError. A Client (and its copies) may be used from several threads at once; an IngestSession
// may not, but several sessions may run at once.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "sglc/client/packing.hpp"
#include "sglc/deskew.hpp"
#include "sglc/types.hpp"
#include "sglc/v1/sglc.grpc.pb.h"
#include "sglc/v1/sglc.pb.h"

namespace sglc::client {

// "OK", "CANCELLED", ..., "UNAUTHENTICATED": the canonical name of a status code.
using wire::statusCodeName;

// A failed call: the status the server (or the gRPC runtime) returned.
// what() is "<method>: <CODE_NAME>: <message>" on one line.
class RpcError : public std::runtime_error {
 public:
  RpcError(std::string method, const grpc::Status& status);
  grpc::StatusCode code() const { return code_; }
  std::string codeName() const { return statusCodeName(code_); }
  const std::string& statusMessage() const { return message_; }
  const std::string& method() const { return method_; }

 private:
  grpc::StatusCode code_;
  std::string message_;
  std::string method_;
};

// The default limit above which ingest() sends a scan with IngestChunked (packed points + labels).
// gRPC servers accept 4 MiB messages by default; 3 MB leaves room for the rest of the request.
inline constexpr std::size_t kDefaultChunkBytes = 3'000'000;

struct ConnectOptions {
  // Bearer token, sent as `authorization: Bearer <token>` on every call (empty: none).
  std::string token;
  // PEM root certificates. Set: the channel uses TLS and verifies the server against them.
  // Empty: plain TCP (only sensible on loopback or a trusted network).
  std::string tls_root_certs;
  // Deadline of each unary call (0: none). IngestSession streams have none unless CallOptions says so.
  std::chrono::milliseconds default_deadline{30'000};
  // Scans whose packed size exceeds this go through IngestChunked, in chunks of at most this size.
  std::size_t chunk_bytes = kDefaultChunkBytes;
  // Attempts of a call that fails with UNAVAILABLE (the server restarting, or a replica behind a balancer that
  // went away), 1..5: gRPC retries it after 0.2 s, doubling up to 5 s. Every call but the deletes and Backup:
  // those read, or are idempotent (ingest of a stored scan answers as the first call did). A stream is retried
  // only before its first answer (IngestSession's callers resend what was not answered; `sglc ingest` does).
  // 1: none.
  int max_attempts = 5;
};

// Per-call override of the deadline. Unset: ConnectOptions::default_deadline. A zero duration: no deadline.
struct CallOptions {
  std::optional<std::chrono::milliseconds> deadline;
};

// What to do with a scan besides storing it.
struct IngestOptions {
  std::optional<double> stamp;         // seconds, the robot's clock
  std::optional<Mat4d> odometry_pose;  // the scan's pose in its session's odometry frame
  bool store_raw = false;              // also keep the raw cloud on the server
  bool query = false;                  // look for loops first (against the scans stored before it)
  v1::QueryOptions query_options;
  // Per-point times (and the twist, when known) for the server to de-skew the scan (sglc.v1.Scan.point_times):
  // leave empty for a scan that is de-skewed already or was taken standing still.
  ScanSweep sweep;
};

// Builders for the small messages.
v1::ScanKey makeKey(const std::string& map, const std::string& robot, const std::string& session, std::int64_t seq);
// Scope names used by the command line: "all" (SCOPE_WHOLE_MAP), "same" (SCOPE_SAME_ROBOT),
// "other" (SCOPE_OTHER_ROBOTS), "sessions" (SCOPE_SESSIONS). Throws InputError on anything else.
v1::Scope parseScope(const std::string& name);
// The full request for Ingest; packs the scan. Throws InputError when point and label counts differ.
v1::IngestRequest makeIngestRequest(const v1::ScanKey& key, const LabelledScan& scan,
                                    const IngestOptions& options = {});

class Client;
namespace detail {
struct ClientCore;  // channel, stubs and options, shared by a Client, its copies and its sessions
}

// One robot's run over the IngestStream RPC: requests are processed in order and each gets one response,
// in the same order. send() queues a scan without waiting; next() returns the oldest outstanding response.
// Keep a bounded number of scans outstanding (e.g. 4-8) to overlap network and server work.
//
// A scan larger than the client's chunk limit does not fit the stream: send() then waits for the
// outstanding responses and stores that scan with IngestChunked, so ordering is kept.
//
// When the server rejects a scan it ends the stream: next() still returns the responses of the scans
// before it (they are stored), then throws RpcError. After an error every call throws it again.
class IngestSession {
 public:
  IngestSession(const IngestSession&) = delete;
  IngestSession& operator=(const IngestSession&) = delete;
  IngestSession(IngestSession&&) noexcept;
  IngestSession& operator=(IngestSession&&) noexcept;
  // Cancels the stream if finish() was not called; scans already answered stay stored.
  ~IngestSession();

  void send(v1::IngestRequest request);
  void send(const v1::ScanKey& key, const LabelledScan& scan, const IngestOptions& options = {});
  // The response to the oldest scan sent and not yet returned. Throws std::logic_error if none is outstanding.
  v1::IngestResponse next();
  // send() + next(), for callers that do not pipeline. Throws std::logic_error if scans are outstanding.
  v1::IngestResponse ingest(v1::IngestRequest request);
  std::size_t outstanding() const { return outstanding_.size(); }
  // Closes the stream: returns the responses still outstanding, then checks the final status (throws RpcError).
  std::vector<v1::IngestResponse> finish();

 private:
  friend class Client;
  struct State;
  IngestSession(std::shared_ptr<const detail::ClientCore> core, const CallOptions& call);
  // Reads whatever the server still has and records the final status as the session's error.
  [[noreturn]] void failStream(const char* what);
  void drainStream();
  struct Outstanding {
    bool in_stream = true;        // response still to be read from the stream
    v1::IngestResponse response;  // when !in_stream: already known (chunked scan)
  };
  std::shared_ptr<const detail::ClientCore> core_;
  std::unique_ptr<State> state_;
  std::deque<Outstanding> outstanding_;
  std::optional<RpcError> error_;
  bool writes_done_ = false;
  bool finished_ = false;
};

class Client {
 public:
  // Connects lazily: the first call establishes the connection (and fails with UNAVAILABLE if it cannot).
  static Client connect(const std::string& address, ConnectOptions options = {});
  // Over an existing channel (tests, custom credentials).
  // Copies share the channel.
  explicit Client(std::shared_ptr<grpc::Channel> channel, ConnectOptions options = {});

  const ConnectOptions& options() const;
  const std::shared_ptr<grpc::Channel>& channel() const;
  // Waits until the channel is connected; false on timeout.
  bool waitForConnected(std::chrono::milliseconds timeout) const;

  // ---- LoopClosure
  // Stores one scan. When the packed scan exceeds options().chunk_bytes it is sent with IngestChunked.
  v1::IngestResponse ingest(const v1::IngestRequest& request, const CallOptions& call = {}) const;
  v1::IngestResponse ingest(const v1::ScanKey& key, const LabelledScan& scan, const IngestOptions& options = {},
                            const CallOptions& call = {}) const;
  // Always chunked (chunks of at most options().chunk_bytes).
  v1::IngestResponse ingestChunked(const v1::IngestRequest& request, const CallOptions& call = {}) const;
  // A robot's run over IngestStream. The stream's deadline is call.deadline (default: none).
  IngestSession openSession(const CallOptions& call = {}) const;

  v1::QueryResponse query(const v1::QueryRequest& request, const CallOptions& call = {}) const;
  // Relocalization: a scan that is not stored. robot/session/seq/stamp of the request stay empty.
  v1::QueryResponse queryScan(const std::string& map, const LabelledScan& scan, const v1::QueryOptions& options = {},
                              const CallOptions& call = {}) const;
  // A stored scan (its robot, session and seq come from the database).
  v1::QueryResponse queryScanId(const std::string& map, std::int64_t scan_id, const v1::QueryOptions& options = {},
                                const CallOptions& call = {}) const;

  // ---- MapAdmin
  v1::MapInfo createMap(const std::string& name, const CallOptions& call = {}) const;
  // Creates the map unless it exists (CreateMap is idempotent; ALREADY_EXISTS: it exists with another layout).
  void ensureMap(const std::string& name, const CallOptions& call = {}) const;
  std::vector<v1::MapInfo> listMaps(const CallOptions& call = {}) const;
  std::vector<v1::RobotInfo> listRobots(const std::string& map, const CallOptions& call = {}) const;
  std::vector<v1::SessionInfo> listSessions(const std::string& map, const std::string& robot = "",
                                            const CallOptions& call = {}) const;
  v1::GetScanResponse getScan(std::int64_t scan_id, bool include_graph = false, const CallOptions& call = {}) const;
  // Return the number of scans removed.
  std::int64_t deleteSession(const std::string& map, const std::string& robot, const std::string& session,
                             const CallOptions& call = {}) const;
  std::int64_t deleteRobot(const std::string& map, const std::string& robot, const CallOptions& call = {}) const;
  // The whole map, irreversibly.
  std::int64_t deleteMap(const std::string& map, const CallOptions& call = {}) const;
  // Empty map: the whole database.
  v1::GetStatsResponse getStats(const std::string& map = "", const CallOptions& call = {}) const;
  // `path` is on the server's filesystem and must not exist yet.
  v1::BackupResponse backup(const std::string& path, const CallOptions& call = {}) const;
  // Applies the map's lifelong policy now (docs/LIFELONG.md).
  v1::CompactResponse compact(const std::string& map, const CallOptions& call = {}) const;

  // ---- PoseGraph
  // Every optimised (or odometry-chained) scan pose of a robot / session / the whole map (empty names), all
  // pages, in scan-id order.
  std::vector<v1::ScanPose> getPoses(const std::string& map, const std::string& robot = "",
                                     const std::string& session = "", const CallOptions& call = {}) const;
  v1::GetSessionFramesResponse getSessionFrames(const std::string& map, const CallOptions& call = {}) const;
  // grpc.health.v1 Check of the whole server: true when SERVING (false while it loads or drains). Needs no
  // token; RpcError when the server cannot be reached.
  bool serving(const CallOptions& call = {}) const;
  // Every verified loop of the map's pose graph (all pages), or those touching `robot`, in id order.
  std::vector<v1::LoopEdge> getLoops(const std::string& map, const std::string& robot = "",
                                     const CallOptions& call = {}) const;
  // The map's pose graph as files (PoseGraph.ExportGraph): name -> contents, in the server's order; `summary`
  // gets the counts when given.
  struct ExportedFile {
    std::string name, data;
  };
  std::vector<ExportedFile> exportGraph(const v1::ExportGraphRequest& request, v1::ExportSummary* summary = nullptr,
                                        const CallOptions& call = {}) const;

 private:
  std::shared_ptr<const detail::ClientCore> core_;
};

}  // namespace sglc::client
