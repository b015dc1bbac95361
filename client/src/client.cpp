#include "sglc/client/client.hpp"

#include <algorithm>
#include <utility>

#include "grpc/health/v1/health.grpc.pb.h"
#include "sglc/rigid.hpp"

namespace sglc::client {

// ---------------------------------------------------------------------------------------------------------
// Errors

namespace {

std::string oneLine(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  std::replace(s.begin(), s.end(), '\r', ' ');
  return s;
}

std::string describe(const std::string& method, const grpc::Status& status) {
  std::string out = statusCodeName(status.error_code());
  if (!status.error_message().empty()) out += ": " + oneLine(status.error_message());
  return out + " (" + method + ")";
}

}  // namespace

RpcError::RpcError(std::string method, const grpc::Status& status)
    : std::runtime_error(describe(method, status)),
      code_(status.error_code()),
      message_(status.error_message()),
      method_(std::move(method)) {}

// ---------------------------------------------------------------------------------------------------------
// Builders

v1::ScanKey makeKey(const std::string& map, const std::string& robot, const std::string& session, std::int64_t seq) {
  v1::ScanKey key;
  key.set_map(map);
  key.set_robot(robot);
  key.set_session(session);
  key.set_seq(seq);
  return key;
}

v1::Scope parseScope(const std::string& name) {
  if (name == "all") return v1::SCOPE_WHOLE_MAP;
  if (name == "same") return v1::SCOPE_SAME_ROBOT;
  if (name == "other") return v1::SCOPE_OTHER_ROBOTS;
  if (name == "sessions") return v1::SCOPE_SESSIONS;
  throw InputError("unknown scope '" + name + "' (expected same, other, all or sessions)");
}

v1::IngestRequest makeIngestRequest(const v1::ScanKey& key, const LabelledScan& scan, const IngestOptions& options) {
  v1::IngestRequest request;
  *request.mutable_key() = key;
  packScan(scan, request.mutable_scan());
  packSweep(options.sweep, request.mutable_scan());
  if (options.stamp) request.set_stamp(*options.stamp);
  if (options.odometry_pose) {
    // The server refuses a pose that is not a rigid motion; say so before sending.
    if (const auto error = rigidMotionError(*options.odometry_pose))
      throw InputError("odometry pose is not a rigid motion: " + *error);
    toTransform(*options.odometry_pose, request.mutable_odometry_pose());
  }
  request.set_store_raw(options.store_raw);
  request.set_query(options.query);
  if (options.query) *request.mutable_query_options() = options.query_options;
  return request;
}

// ---------------------------------------------------------------------------------------------------------
// Shared core

namespace detail {

struct ClientCore {
  ConnectOptions options;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<v1::LoopClosure::Stub> loop;
  std::unique_ptr<v1::MapAdmin::Stub> admin;
  std::unique_ptr<v1::PoseGraph::Stub> graph;
  std::unique_ptr<grpc::health::v1::Health::Stub> health;

  void prepare(grpc::ClientContext* context, const CallOptions& call, bool stream) const {
    const auto deadline = call.deadline.value_or(stream ? std::chrono::milliseconds(0) : options.default_deadline);
    if (deadline.count() > 0) context->set_deadline(std::chrono::system_clock::now() + deadline);
    if (!options.token.empty()) context->AddMetadata("authorization", "Bearer " + options.token);
  }

  template <typename Stub, typename Request, typename Response>
  Response unary(Stub* stub, grpc::Status (Stub::*method)(grpc::ClientContext*, const Request&, Response*),
                 const char* name, const Request& request, const CallOptions& call) const {
    grpc::ClientContext context;
    prepare(&context, call, false);
    Response response;
    const grpc::Status status = (stub->*method)(&context, request, &response);
    if (!status.ok()) throw RpcError(name, status);
    return response;
  }

  v1::IngestResponse ingestChunked(const v1::IngestRequest& request, const CallOptions& call) const {
    const auto chunks = splitIntoChunks(request, options.chunk_bytes);
    grpc::ClientContext context;
    prepare(&context, call, false);
    v1::IngestResponse response;
    auto writer = loop->IngestChunked(&context, &response);
    for (const auto& chunk : chunks)
      if (!writer->Write(chunk)) break;  // the server ended the call: Finish() says why
    writer->WritesDone();
    const grpc::Status status = writer->Finish();
    if (!status.ok()) throw RpcError("LoopClosure.IngestChunked", status);
    return response;
  }
};

}  // namespace detail

// ---------------------------------------------------------------------------------------------------------
// Client

namespace {

// gRPC's retry policy for every service of ours (and health checks): UNAVAILABLE only.
std::string retryServiceConfig(int max_attempts) {
  // Not the deletes or Backup: a delete whose answer was lost would be repeated (NOT_FOUND, or worse, a map
  // created again under the name meanwhile deleted), a backup would dump again.
  return R"({"methodConfig": [{"name": [{"service": "sglc.v1.LoopClosure"}, {"service": "sglc.v1.PoseGraph"},)"
         R"( {"service": "grpc.health.v1.Health"}, {"service": "sglc.v1.MapAdmin", "method": "GetServerInfo"},)"
         R"( {"service": "sglc.v1.MapAdmin", "method": "CreateMap"},)"
         R"( {"service": "sglc.v1.MapAdmin", "method": "ListMaps"},)"
         R"( {"service": "sglc.v1.MapAdmin", "method": "ListRobots"},)"
         R"( {"service": "sglc.v1.MapAdmin", "method": "ListSessions"},)"
         R"( {"service": "sglc.v1.MapAdmin", "method": "GetScan"},)"
         R"( {"service": "sglc.v1.MapAdmin", "method": "GetStats"}],)"
         R"( "retryPolicy": {"maxAttempts": )" +
         std::to_string(max_attempts) +
         R"(, "initialBackoff": "0.2s", "maxBackoff": "5s", "backoffMultiplier": 2,)"
         R"( "retryableStatusCodes": ["UNAVAILABLE"]}}]})";
}

}  // namespace

Client Client::connect(const std::string& address, ConnectOptions options) {
  if (address.empty()) throw InputError("empty server address");
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  if (options.tls_root_certs.empty()) {
    credentials = grpc::InsecureChannelCredentials();
  } else {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = options.tls_root_certs;
    credentials = grpc::SslCredentials(ssl);
  }
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(-1);  // responses (graphs, many candidates) are not capped on our side
  args.SetMaxSendMessageSize(-1);     // the chunk limit keeps requests small enough for the server
  if (options.max_attempts < 1 || options.max_attempts > 5) throw InputError("max_attempts must be 1..5");
  if (options.max_attempts > 1) {
    args.SetServiceConfigJSON(retryServiceConfig(options.max_attempts));
    // A call is retried only while its request is buffered: room for one chunk (or one whole small scan).
    args.SetInt(GRPC_ARG_PER_RPC_RETRY_BUFFER_SIZE,
                static_cast<int>(std::min<std::size_t>(options.chunk_bytes + (1 << 20), 1 << 30)));
  }
  return Client(grpc::CreateCustomChannel(address, credentials, args), std::move(options));
}

Client::Client(std::shared_ptr<grpc::Channel> channel, ConnectOptions options) {
  if (!channel) throw InputError("null gRPC channel");
  if (options.chunk_bytes < kPointBytes + kLabelBytes)
    throw InputError("chunk size " + std::to_string(options.chunk_bytes) + " bytes is below one point (16 bytes)");
  auto core = std::make_shared<detail::ClientCore>();
  core->options = std::move(options);
  core->channel = std::move(channel);
  core->loop = v1::LoopClosure::NewStub(core->channel);
  core->admin = v1::MapAdmin::NewStub(core->channel);
  core->graph = v1::PoseGraph::NewStub(core->channel);
  core->health = grpc::health::v1::Health::NewStub(core->channel);
  core_ = std::move(core);
}

const ConnectOptions& Client::options() const { return core_->options; }
const std::shared_ptr<grpc::Channel>& Client::channel() const { return core_->channel; }

bool Client::waitForConnected(std::chrono::milliseconds timeout) const {
  return core_->channel->WaitForConnected(std::chrono::system_clock::now() + timeout);
}

v1::IngestResponse Client::ingest(const v1::IngestRequest& request, const CallOptions& call) const {
  if (packedSize(request.scan()) > core_->options.chunk_bytes) return core_->ingestChunked(request, call);
  return core_->unary(core_->loop.get(), &v1::LoopClosure::Stub::Ingest, "LoopClosure.Ingest", request, call);
}

v1::IngestResponse Client::ingest(const v1::ScanKey& key, const LabelledScan& scan, const IngestOptions& options,
                                  const CallOptions& call) const {
  return ingest(makeIngestRequest(key, scan, options), call);
}

v1::IngestResponse Client::ingestChunked(const v1::IngestRequest& request, const CallOptions& call) const {
  return core_->ingestChunked(request, call);
}

IngestSession Client::openSession(const CallOptions& call) const { return IngestSession(core_, call); }

v1::QueryResponse Client::query(const v1::QueryRequest& request, const CallOptions& call) const {
  return core_->unary(core_->loop.get(), &v1::LoopClosure::Stub::Query, "LoopClosure.Query", request, call);
}

v1::QueryResponse Client::queryScan(const std::string& map, const LabelledScan& scan, const v1::QueryOptions& options,
                                    const CallOptions& call) const {
  v1::QueryRequest request;
  request.set_map(map);
  packScan(scan, request.mutable_scan());
  *request.mutable_options() = options;
  return query(request, call);
}

v1::QueryResponse Client::queryScanId(const std::string& map, std::int64_t scan_id, const v1::QueryOptions& options,
                                      const CallOptions& call) const {
  v1::QueryRequest request;
  request.set_map(map);
  request.set_scan_id(scan_id);
  *request.mutable_options() = options;
  return query(request, call);
}

v1::MapInfo Client::createMap(const std::string& name, const CallOptions& call) const {
  v1::CreateMapRequest request;
  request.set_name(name);
  return core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::CreateMap, "MapAdmin.CreateMap", request, call);
}

void Client::ensureMap(const std::string& name, const CallOptions& call) const {
  // CreateMap is idempotent; its ALREADY_EXISTS means the map was made by another engine configuration (another
  // descriptor layout), which the caller must hear about.
  createMap(name, call);
}

std::vector<v1::MapInfo> Client::listMaps(const CallOptions& call) const {
  const auto r =
      core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::ListMaps, "MapAdmin.ListMaps", v1::ListMapsRequest{}, call);
  return {r.maps().begin(), r.maps().end()};
}

std::vector<v1::RobotInfo> Client::listRobots(const std::string& map, const CallOptions& call) const {
  v1::ListRobotsRequest request;
  request.set_map(map);
  const auto r =
      core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::ListRobots, "MapAdmin.ListRobots", request, call);
  return {r.robots().begin(), r.robots().end()};
}

std::vector<v1::SessionInfo> Client::listSessions(const std::string& map, const std::string& robot,
                                                  const CallOptions& call) const {
  v1::ListSessionsRequest request;
  request.set_map(map);
  request.set_robot(robot);
  const auto r =
      core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::ListSessions, "MapAdmin.ListSessions", request, call);
  return {r.sessions().begin(), r.sessions().end()};
}

v1::GetScanResponse Client::getScan(std::int64_t scan_id, bool include_graph, const CallOptions& call) const {
  v1::GetScanRequest request;
  request.set_scan_id(scan_id);
  request.set_include_graph(include_graph);
  return core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::GetScan, "MapAdmin.GetScan", request, call);
}

std::int64_t Client::deleteSession(const std::string& map, const std::string& robot, const std::string& session,
                                   const CallOptions& call) const {
  v1::DeleteSessionRequest request;
  request.set_map(map);
  request.set_robot(robot);
  request.set_session(session);
  return core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::DeleteSession, "MapAdmin.DeleteSession", request, call)
      .scans_removed();
}

std::int64_t Client::deleteRobot(const std::string& map, const std::string& robot, const CallOptions& call) const {
  v1::DeleteRobotRequest request;
  request.set_map(map);
  request.set_robot(robot);
  return core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::DeleteRobot, "MapAdmin.DeleteRobot", request, call)
      .scans_removed();
}

std::int64_t Client::deleteMap(const std::string& map, const CallOptions& call) const {
  v1::DeleteMapRequest request;
  request.set_map(map);
  return core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::DeleteMap, "MapAdmin.DeleteMap", request, call)
      .scans_removed();
}

v1::GetStatsResponse Client::getStats(const std::string& map, const CallOptions& call) const {
  v1::GetStatsRequest request;
  request.set_map(map);
  return core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::GetStats, "MapAdmin.GetStats", request, call);
}

namespace {

// Page tokens only grow (they are the last id returned): a server that answers otherwise would keep a client
// paging forever.
void checkNextPage(const std::string& method, std::int64_t token, std::int64_t next) {
  if (next != 0 && next <= token)
    throw RpcError(method,
                   grpc::Status(grpc::StatusCode::INTERNAL, "the server's next_page_token " + std::to_string(next) +
                                                                " does not follow " + std::to_string(token)));
}

}  // namespace

std::vector<v1::ScanPose> Client::getPoses(const std::string& map, const std::string& robot, const std::string& session,
                                           const CallOptions& call) const {
  std::vector<v1::ScanPose> out;
  v1::GetPosesRequest request;
  request.set_map(map);
  request.set_robot(robot);
  request.set_session(session);
  request.set_page_size(5000);
  do {
    auto page = core_->unary(core_->graph.get(), &v1::PoseGraph::Stub::GetPoses, "PoseGraph.GetPoses", request, call);
    for (auto& p : *page.mutable_poses()) out.push_back(std::move(p));
    checkNextPage("PoseGraph.GetPoses", request.page_token(), page.next_page_token());
    request.set_page_token(page.next_page_token());
  } while (request.page_token() != 0);
  return out;
}

bool Client::serving(const CallOptions& call) const {
  grpc::health::v1::HealthCheckRequest request;  // "": the server as a whole
  const auto r =
      core_->unary(core_->health.get(), &grpc::health::v1::Health::Stub::Check, "Health.Check", request, call);
  return r.status() == grpc::health::v1::HealthCheckResponse::SERVING;
}

std::vector<v1::LoopEdge> Client::getLoops(const std::string& map, const std::string& robot,
                                           const CallOptions& call) const {
  std::vector<v1::LoopEdge> out;
  v1::GetLoopsRequest request;
  request.set_map(map);
  request.set_robot(robot);
  request.set_page_size(5000);
  do {
    auto page = core_->unary(core_->graph.get(), &v1::PoseGraph::Stub::GetLoops, "PoseGraph.GetLoops", request, call);
    for (auto& l : *page.mutable_loops()) out.push_back(std::move(l));
    checkNextPage("PoseGraph.GetLoops", request.page_token(), page.next_page_token());
    request.set_page_token(page.next_page_token());
  } while (request.page_token() != 0);
  return out;
}

std::vector<Client::ExportedFile> Client::exportGraph(const v1::ExportGraphRequest& request, v1::ExportSummary* summary,
                                                      const CallOptions& call) const {
  grpc::ClientContext context;
  core_->prepare(&context, call, false);
  auto reader = core_->graph->ExportGraph(&context, request);
  std::vector<ExportedFile> files;
  v1::ExportChunk chunk;
  while (reader->Read(&chunk)) {
    if (chunk.has_summary() && summary) *summary = chunk.summary();
    if (files.empty() || files.back().name != chunk.file()) files.push_back({chunk.file(), {}});
    files.back().data += chunk.data();
  }
  const grpc::Status status = reader->Finish();
  if (!status.ok()) throw RpcError("PoseGraph.ExportGraph", status);
  return files;
}

v1::GetSessionFramesResponse Client::getSessionFrames(const std::string& map, const CallOptions& call) const {
  v1::GetSessionFramesRequest request;
  request.set_map(map);
  return core_->unary(core_->graph.get(), &v1::PoseGraph::Stub::GetSessionFrames, "PoseGraph.GetSessionFrames", request,
                      call);
}

v1::BackupResponse Client::backup(const std::string& path, const CallOptions& call) const {
  v1::BackupRequest request;
  request.set_path(path);
  return core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::Backup, "MapAdmin.Backup", request, call);
}

v1::CompactResponse Client::compact(const std::string& map, const CallOptions& call) const {
  v1::CompactRequest request;
  request.set_map(map);
  return core_->unary(core_->admin.get(), &v1::MapAdmin::Stub::Compact, "MapAdmin.Compact", request, call);
}

// ---------------------------------------------------------------------------------------------------------
// IngestSession

struct IngestSession::State {
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReaderWriter<v1::IngestRequest, v1::IngestResponse>> stream;
};

namespace {
constexpr const char* kStreamMethod = "LoopClosure.IngestStream";
}

IngestSession::IngestSession(std::shared_ptr<const detail::ClientCore> core, const CallOptions& call)
    : core_(std::move(core)), state_(std::make_unique<State>()) {
  core_->prepare(&state_->context, call, true);
  state_->stream = core_->loop->IngestStream(&state_->context);
}

IngestSession::IngestSession(IngestSession&&) noexcept = default;
IngestSession& IngestSession::operator=(IngestSession&& other) noexcept {
  if (this != &other) {
    IngestSession previous(std::move(*this));  // its stream (if any) is cancelled when it goes out of scope
    core_ = std::move(other.core_);
    state_ = std::move(other.state_);
    outstanding_ = std::move(other.outstanding_);
    error_ = std::move(other.error_);
    writes_done_ = other.writes_done_;
    finished_ = other.finished_;
  }
  return *this;
}

IngestSession::~IngestSession() {
  if (!state_ || finished_) return;
  // Abandoned: cancel, consume what is left and collect the status so the call is released cleanly.
  state_->context.TryCancel();
  v1::IngestResponse ignored;
  while (state_->stream->Read(&ignored)) {
  }
  state_->stream->Finish();
}

void IngestSession::failStream(const char* what) {
  // The stream is dead. Responses already on their way belong to scans that were stored: keep them.
  std::deque<Outstanding> kept;
  for (auto& o : outstanding_) {
    if (!o.in_stream) {
      kept.push_back(std::move(o));
      continue;
    }
    Outstanding known;
    known.in_stream = false;
    if (!state_->stream->Read(&known.response)) break;
    kept.push_back(std::move(known));
  }
  v1::IngestResponse extra;
  while (state_->stream->Read(&extra)) {
  }
  grpc::Status status = state_->stream->Finish();
  finished_ = true;
  if (status.ok())
    status = grpc::Status(grpc::StatusCode::INTERNAL, std::string("the server closed the stream ") + what);
  outstanding_ = std::move(kept);
  error_.emplace(kStreamMethod, status);
  throw *error_;
}

void IngestSession::drainStream() {
  for (auto& o : outstanding_) {
    if (!o.in_stream) continue;
    if (!state_->stream->Read(&o.response)) failStream("before answering every scan");
    o.in_stream = false;
  }
}

void IngestSession::send(v1::IngestRequest request) {
  if (!state_) throw std::logic_error("IngestSession: use of a moved-from session");
  if (error_) throw *error_;
  if (writes_done_ || finished_) throw std::logic_error("IngestSession: send() after finish()");
  if (packedSize(request.scan()) > core_->options.chunk_bytes) {
    drainStream();  // keep the order: everything sent before is processed first
    Outstanding o;
    o.in_stream = false;
    try {
      o.response = core_->ingestChunked(request, CallOptions{});
    } catch (const RpcError& e) {
      // A rejected scan ends the session, as it would on the stream.
      error_ = e;
      throw;
    }
    outstanding_.push_back(std::move(o));
    return;
  }
  if (!state_->stream->Write(request)) failStream("while scans were being sent");
  outstanding_.push_back(Outstanding{});
}

void IngestSession::send(const v1::ScanKey& key, const LabelledScan& scan, const IngestOptions& options) {
  send(makeIngestRequest(key, scan, options));
}

v1::IngestResponse IngestSession::next() {
  if (!state_) throw std::logic_error("IngestSession: use of a moved-from session");
  if (outstanding_.empty()) {
    if (error_) throw *error_;
    throw std::logic_error("IngestSession: next() with no scan outstanding");
  }
  Outstanding& front = outstanding_.front();
  if (front.in_stream && !state_->stream->Read(&front.response)) failStream("before answering every scan");
  v1::IngestResponse response = std::move(front.response);
  outstanding_.pop_front();
  return response;
}

v1::IngestResponse IngestSession::ingest(v1::IngestRequest request) {
  if (!outstanding_.empty()) throw std::logic_error("IngestSession: ingest() while scans are outstanding");
  send(std::move(request));
  return next();
}

std::vector<v1::IngestResponse> IngestSession::finish() {
  if (!state_) throw std::logic_error("IngestSession: use of a moved-from session");
  if (error_) throw *error_;
  if (finished_) return {};
  if (!writes_done_) {
    state_->stream->WritesDone();
    writes_done_ = true;
  }
  std::vector<v1::IngestResponse> rest;
  while (!outstanding_.empty()) rest.push_back(next());
  v1::IngestResponse extra;
  while (state_->stream->Read(&extra)) {
  }
  const grpc::Status status = state_->stream->Finish();
  finished_ = true;
  if (!status.ok()) {
    error_.emplace(kStreamMethod, status);
    throw *error_;
  }
  return rest;
}

}  // namespace sglc::client
