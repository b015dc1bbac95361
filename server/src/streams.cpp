// The streaming RPCs as callback reactors: an open stream holds no thread while it waits for its client.
//
// Each reactor reads raw bytes and parses them itself, so a message that is not valid protobuf fails the call
// with INVALID_ARGUMENT instead of looking like the client's half-close (which silently dropped the rest of a
// stream before). Blocking work (fingerprint, query, store) runs on the service's Executor; reactions only
// start reads and writes. gRPC may run a reaction inline inside a Start*/Finish call, so no gRPC operation is
// started while a reactor's mutex is held.
#include <spdlog/spdlog.h>

#include <optional>

#include "call.hpp"
#include "service.hpp"

namespace sglc::server {
namespace {

using Bytes = grpc::ByteBuffer;
using SteadyTime = std::chrono::steady_clock::time_point;

// Finishing exactly once (after the work or write in flight, if any), the log line, and the stream's place
// in the registry.
template <class Base>
class StreamReactor : public Base, public RegisteredStream {
 public:
  void OnCancel() override { finish(grpc::Status(grpc::StatusCode::CANCELLED, "the client cancelled the call")); }
  void OnDone() override {
    state_.streams().leave(id_);
    unref();
  }
  void close(const grpc::Status& status) override { finish(status); }
  std::optional<SteadyTime> idleSince() override {
    std::lock_guard lock(mutex_);
    if (busy_ || writing_ || starting_ || finishing_) return std::nullopt;
    return last_;
  }

 protected:
  StreamReactor(ServiceState& state, grpc::CallbackServerContext* ctx, const char* method)
      : state_(state), ctx_(ctx), log_{method, "", ""} {
    log_.messages = 0;
  }

  // Authenticates and takes a place in the registry; false (and finished) when refused.
  bool admit(StreamRegistry::Kind kind) {
    try {
      grant_ = state_.tokens().authenticate(*ctx_);
      id_ = state_.streams().admit(kind, StreamRegistry::clientOf(*ctx_, state_.tokens().enabled()), this);
      return true;
    } catch (...) {
      complete(std::current_exception());
      return false;
    }
  }

  // Asks the stream to end with `status`; deferred while work, a write or a read being started is in flight
  // (they end it).
  void finish(const grpc::Status& status) {
    {
      std::lock_guard lock(mutex_);
      if (finishing_) return;
      finishing_ = true;
      status_ = status;
      if (busy_ || writing_ || starting_) return;
    }
    finishNow();
  }
  // The work in flight ended with this status, which is final (it overrides a deferred request to end, but not
  // a Finish already sent).
  void complete(const grpc::Status& status, const std::string& detail = "") {
    {
      std::lock_guard lock(mutex_);
      busy_ = false;
      if (finished_) return;
      finishing_ = true;
      status_ = status;
      detail_ = detail;
    }
    finishNow();
  }
  void complete(std::exception_ptr error) {
    std::string detail;
    const auto status = statusOf(error, &detail);
    complete(status, detail);
  }
  // Sends Finish once (a second Finish would abort the process inside gRPC). Never with mutex_ held.
  void finishNow() {
    {
      std::lock_guard lock(mutex_);
      if (finished_) return;
      finished_ = true;
    }
    logCall(*ctx_, log_, status_, detail_);
    this->Finish(status_);
  }
  // Starts the next read from outside a gRPC reaction (an executor thread): the stream counts as starting a
  // read meanwhile, so a request to end it waits for the read to be started and then ends it here.
  void startReadFromWorker(Bytes* into) {
    bool end_now;
    {
      std::lock_guard lock(mutex_);
      busy_ = false;
      end_now = finishing_;
      if (!end_now) starting_ = true;
    }
    if (end_now) {
      finishNow();
      return;
    }
    this->StartRead(into);
    bool end;
    {
      std::lock_guard lock(mutex_);
      starting_ = false;
      end = finishing_ && !busy_ && !writing_;
    }
    if (end) finishNow();
  }
  // Posts blocking work; the reactor stays alive until it has run.
  template <typename F>
  void post(F&& work) {
    ref();
    state_.executor().post([this, work = std::forward<F>(work)]() mutable {
      work();
      unref();
    });
  }

  ServiceState& state_;
  grpc::CallbackServerContext* ctx_;
  CallLog log_;
  TokenTable::Grant grant_;
  std::uint64_t id_ = 0;
  std::mutex mutex_;
  bool busy_ = false, writing_ = false, starting_ = false, finishing_ = false, finished_ = false;
  SteadyTime last_ = std::chrono::steady_clock::now();
  grpc::Status status_;
  std::string detail_;
};

// ------------------------------------------------------------------------------------------------ IngestStream

class IngestStreamReactor final : public StreamReactor<grpc::ServerBidiReactor<Bytes, Bytes>> {
 public:
  IngestStreamReactor(ServiceState& state, grpc::CallbackServerContext* ctx)
      : StreamReactor(state, ctx, "IngestStream") {
    if (admit(StreamRegistry::Kind::kIngest)) StartRead(&in_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client half-closed, or the call broke
      finish(ctx_->IsCancelled() ? grpc::Status(grpc::StatusCode::CANCELLED, "the stream broke") : grpc::Status::OK);
      return;
    }
    {
      std::lock_guard lock(mutex_);
      if (finishing_) return;  // ended meanwhile (idle timeout, shutdown): Finish was called
      busy_ = true;
    }
    // The message's memory is reserved before it is parsed (a parsed copy doubles it), on a worker: waiting for
    // memory must not block a gRPC thread.
    post([this] { process(); });
  }

  void OnWriteDone(bool ok) override {
    bool end;
    {
      std::lock_guard lock(mutex_);
      writing_ = false;
      busy_ = false;
      last_ = std::chrono::steady_clock::now();
      if (!ok && !finishing_) {
        finishing_ = true;
        status_ = grpc::Status(grpc::StatusCode::CANCELLED, "the client closed the stream");
      }
      end = finishing_;
    }
    if (end)
      finishNow();
    else
      StartRead(&in_);
  }

 private:
  void process() {
    v1::IngestResponse resp;
    try {
      auto lease = state_.memory().acquire(in_.Length() * kScanCostFactor, ctx_->deadline(),
                                           [this] { return ctx_->IsCancelled(); });
      const auto req = parseMessage<v1::IngestRequest>(
          in_, "message " + std::to_string(log_.messages + 1) + " of the stream (earlier scans are stored)");
      in_.Clear();
      log_.map = req.key().map();
      log_.robot = req.key().robot();
      ingestScan(state_, ctx_, grant_, req, req.scan().points(), req.scan().labels(), req.scan().point_times(), &resp,
                 &lease);
    } catch (...) {
      complete(std::current_exception());
      return;
    }
    ++log_.messages;
    serializeMessage(resp, &out_);
    {
      std::lock_guard lock(mutex_);
      writing_ = true;  // the response goes out even when the stream is asked to end meanwhile
    }
    StartWrite(&out_);
  }

  Bytes in_, out_;
};

// ------------------------------------------------------------------------------------------------ IngestChunked

class IngestChunkedReactor final : public StreamReactor<grpc::ServerReadReactor<Bytes>> {
 public:
  IngestChunkedReactor(ServiceState& state, grpc::CallbackServerContext* ctx, Bytes* response)
      : StreamReactor(state, ctx, "IngestChunked"), response_(response) {
    if (admit(StreamRegistry::Kind::kIngest)) StartRead(&in_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      if (ctx_->IsCancelled()) {
        finish(grpc::Status(grpc::StatusCode::CANCELLED, "the stream broke before it ended; nothing was stored"));
        return;
      }
      if (!log_.messages) {
        complete(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "no chunks received"));
        return;
      }
      if (!begin()) return;
      post([this] { process(); });
      return;
    }
    bool progress = false;
    try {
      progress = append();
    } catch (...) {
      complete(std::current_exception());
      return;
    }
    if (log_.messages == 1) {
      // The whole scan's memory is reserved once, up front (the most the server accepts; returned down to the
      // real size when the scan is complete): an upload that grew chunk by chunk could hold part of the budget
      // while waiting behind a call that waits for it. Waiting happens on a worker, never on a gRPC thread.
      if (!begin()) return;
      post([this] {
        try {
          lease_ = state_.memory().acquire(maxBytes() * kScanCostFactor, ctx_->deadline(),
                                           [this] { return ctx_->IsCancelled(); });
        } catch (...) {
          complete(std::current_exception());
          return;
        }
        startReadFromWorker(&in_);
      });
      return;
    }
    {
      std::lock_guard lock(mutex_);
      if (progress) last_ = std::chrono::steady_clock::now();  // empty chunks do not keep a stream alive
      if (finishing_) return;
    }
    StartRead(&in_);
  }

 private:
  // A whole scan of the most points allowed: 12 bytes of point, 4 of label, 4 of time each (and slack).
  std::size_t maxBytes() const { return state_.limits().max_points * 20 + 16; }

  // Marks work in flight; false when the stream is ending (Finish was called).
  bool begin() {
    std::lock_guard lock(mutex_);
    if (finishing_) return false;
    busy_ = true;
    return true;
  }

  // Parses the chunk just read and appends it; returns whether it carried any bytes.
  bool append() {
    ++log_.messages;
    auto chunk = parseMessage<v1::IngestChunk>(
        in_, "chunk " + std::to_string(log_.messages) + " of the stream (nothing of the scan was stored)");
    in_.Clear();
    const std::size_t before = payloadBytes();
    if (log_.messages == 1) {
      if (!chunk.has_header())
        throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "the first chunk must carry the header");
      header_ = std::move(*chunk.mutable_header());
      log_.map = header_.key().map();
      log_.robot = header_.key().robot();
      TokenTable::require(grant_, header_.key().map());
      points_ = std::move(*header_.mutable_scan()->mutable_points());
      labels_ = std::move(*header_.mutable_scan()->mutable_labels());
      times_ = std::move(*header_.mutable_scan()->mutable_point_times());
    } else if (chunk.has_header()) {
      throw RpcError(grpc::StatusCode::INVALID_ARGUMENT, "only the first chunk may carry a header");
    }
    points_ += chunk.points();
    labels_ += chunk.labels();
    times_ += chunk.point_times();
    if (payloadBytes() > maxBytes())
      throw RpcError(grpc::StatusCode::RESOURCE_EXHAUSTED, "chunked scan exceeds the server's point limit (" +
                                                               std::to_string(state_.limits().max_points) + ")");
    return payloadBytes() > before || log_.messages == 1;
  }

  void process() {
    v1::IngestResponse resp;
    try {
      state_.memory().shrink(lease_, payloadBytes() * kScanCostFactor);
      ingestScan(state_, ctx_, grant_, header_, points_, labels_, times_, &resp, &lease_);
    } catch (...) {
      complete(std::current_exception());
      return;
    }
    serializeMessage(resp, response_);
    complete(grpc::Status::OK);
  }

  Bytes* response_;
  Bytes in_;
  v1::IngestRequest header_;
  std::size_t payloadBytes() const { return points_.size() + labels_.size() + times_.size(); }

  std::string points_, labels_, times_;
  MemoryBudget::Lease lease_;
};

// ------------------------------------------------------------------------------------------------ WatchMap

class WatchMapReactor final : public StreamReactor<grpc::ServerWriteReactor<Bytes>> {
 public:
  WatchMapReactor(ServiceState& state, grpc::CallbackServerContext* ctx, const Bytes* request)
      : StreamReactor(state, ctx, "WatchMap") {
    try {
      const auto req = parseMessage<v1::WatchMapRequest>(*request, "the request");
      map_ = req.map();
      after_ = req.after_version();
      log_.map = map_;
      map_id_ = requireMap(state_, ctx_, map_).id;
      graph_ = state_.graph();
      if (!graph_ || graph_->stopping())
        throw RpcError(grpc::StatusCode::UNAVAILABLE, "the pose graph is loading or the server is shutting down");
    } catch (...) {
      complete(std::current_exception());
      return;
    }
    if (!admit(StreamRegistry::Kind::kWatch)) return;
    subscription_ = graph_->subscribe([this](const std::string& map, const GraphEvent& e) {
      if (map == map_) deliver(e);
    });
    // Deleted between the check above and the subscription: no deletion event will come.
    std::int64_t now = map_id_;
    try {
      now = mapId();
    } catch (const std::exception&) {
      // the database failed: watch on (a deletion still ends the watch)
    }
    if (now != map_id_) {
      post([this] { finish(deletedStatus()); });
      return;
    }
    if (const auto e = graph_->latest(map_)) deliver(*e);
  }

  void OnDone() override {
    // Never inside the graph's publish (events are written from the executor), so this cannot deadlock.
    if (subscription_) graph_->unsubscribe(subscription_);
    StreamReactor::OnDone();
  }
  // A watcher waits for events, not for its client: never idle.
  std::optional<SteadyTime> idleSince() override { return std::nullopt; }

  void OnWriteDone(bool ok) override {
    bool end, next = false;
    {
      std::lock_guard lock(mutex_);
      writing_ = false;
      if (!ok && !finishing_) {
        finishing_ = true;
        status_ = grpc::Status(grpc::StatusCode::CANCELLED, "the client went away");
      }
      end = finishing_;
      if (!end && pending_) next = take();
    }
    if (end)
      finishNow();
    else if (next)
      StartWrite(&out_);
  }

 private:
  // A new event: the newest one waits while a write is in flight; otherwise it is written from the executor.
  void deliver(const GraphEvent& e) {
    if (e.deleted) {  // ended from the executor: never inside the graph's publish (see OnDone)
      if (e.map_id == map_id_) post([this] { finish(deletedStatus()); });
      return;  // another map of the name (deleted before this one was made)
    }
    {
      std::lock_guard lock(mutex_);
      if (finishing_ || (!e.failed && e.graph_version <= after_)) return;
      pending_ = e;
      if (writing_ || !take()) return;
    }
    post([this] { StartWrite(&out_); });
  }
  // Serialises the pending event into out_ and marks the write (mutex held).
  bool take() {
    v1::MapEvent m;
    m.set_graph_version(pending_->graph_version);
    m.set_loops(pending_->loops);
    m.set_nodes(pending_->nodes);
    m.set_rejected_loops(pending_->rejected_loops);
    m.set_optimise_ms(pending_->optimise_ms);
    m.set_converged(pending_->converged);
    m.set_failed(pending_->failed);
    m.set_error(pending_->error);
    if (!pending_->failed) after_ = pending_->graph_version;
    pending_.reset();
    serializeMessage(m, &out_);
    ++log_.messages;
    writing_ = true;
    return true;
  }

  // The id of the map named map_ now (0: none). Throws when the database fails.
  std::int64_t mapId() const {
    const auto info = state_.store().findMap(map_);
    return info ? info->id : 0;
  }
  grpc::Status deletedStatus() const {
    return grpc::Status(grpc::StatusCode::NOT_FOUND, "map '" + map_ + "' was deleted");
  }

  std::string map_;
  std::int64_t map_id_ = 0;
  std::int64_t after_ = 0;
  GraphOptimiser* graph_ = nullptr;
  std::uint64_t subscription_ = 0;
  std::optional<GraphEvent> pending_;
  Bytes out_;
};

}  // namespace

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* LoopClosureService::IngestStream(
    grpc::CallbackServerContext* ctx) {
  return new IngestStreamReactor(state_, ctx);
}

grpc::ServerReadReactor<grpc::ByteBuffer>* LoopClosureService::IngestChunked(grpc::CallbackServerContext* ctx,
                                                                             grpc::ByteBuffer* resp) {
  return new IngestChunkedReactor(state_, ctx, resp);
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* PoseGraphService::WatchMap(grpc::CallbackServerContext* ctx,
                                                                       const grpc::ByteBuffer* req) {
  return new WatchMapReactor(state_, ctx, req);
}

}  // namespace sglc::server
