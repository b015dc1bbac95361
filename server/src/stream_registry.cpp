#include "stream_registry.hpp"

#include <functional>
#include <vector>

#include "rpc_error.hpp"

namespace sglc::server {

StreamRegistry::StreamRegistry(StreamLimits limits, std::function<void()> housekeeping)
    : limits_(limits), housekeeping_(std::move(housekeeping)) {
  thread_ = std::thread([this] { housekeepingLoop(); });
}

StreamRegistry::~StreamRegistry() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  stop_cv_.notify_all();
  thread_.join();
}

std::uint64_t StreamRegistry::admit(Kind kind, const std::string& client, RegisteredStream* stream) {
  std::lock_guard lock(mutex_);
  const char* what = kind == Kind::kIngest ? "ingest" : "WatchMap";
  if (closed_) throw RpcError(grpc::StatusCode::UNAVAILABLE, "the server is shutting down");
  if (per_kind_[kind] >= limits_.max_total)
    throw RpcError(grpc::StatusCode::RESOURCE_EXHAUSTED, std::string("the server has its limit of ") +
                                                             std::to_string(limits_.max_total) + " open " + what +
                                                             " streams; close one or retry later");
  auto& mine = per_client_[{kind, client}];
  if (mine >= limits_.max_per_client)
    throw RpcError(grpc::StatusCode::RESOURCE_EXHAUSTED, std::string("this client already holds ") +
                                                             std::to_string(mine) + " open " + what +
                                                             " streams, the most one client may (close one first)");
  ++mine;
  ++per_kind_[kind];
  const auto id = next_id_++;
  streams_[id] = {kind, client, stream};
  return id;
}

void StreamRegistry::leave(std::uint64_t id) {
  std::lock_guard lock(mutex_);
  const auto it = streams_.find(id);
  if (it == streams_.end()) return;
  const auto key = std::make_pair(it->second.kind, it->second.client);
  if (--per_client_[key] == 0) per_client_.erase(key);
  --per_kind_[it->second.kind];
  streams_.erase(it);
}

int StreamRegistry::open(Kind kind) const {
  std::lock_guard lock(mutex_);
  const auto it = per_kind_.find(kind);
  return it == per_kind_.end() ? 0 : it->second;
}

void StreamRegistry::closeAll(const grpc::Status& status) {
  std::vector<RegisteredStream*> all;
  {
    std::lock_guard lock(mutex_);
    closed_ = true;
    for (auto& [id, e] : streams_) {
      e.stream->ref();
      all.push_back(e.stream);
    }
  }
  for (auto* s : all) {
    s->close(status);
    s->unref();
  }
}

void StreamRegistry::housekeepingLoop() {
  std::unique_lock lock(mutex_);
  while (!stop_) {
    stop_cv_.wait_for(lock, std::chrono::seconds(1));
    if (stop_) return;
    const auto now = std::chrono::steady_clock::now();
    std::vector<RegisteredStream*> idle;
    for (auto& [id, e] : streams_) {
      if (e.kind != Kind::kIngest) continue;
      const auto since = e.stream->idleSince();
      if (since && now - *since > limits_.idle_timeout) {
        e.stream->ref();
        idle.push_back(e.stream);
      }
    }
    lock.unlock();
    const auto seconds = std::chrono::duration_cast<std::chrono::seconds>(limits_.idle_timeout).count();
    for (auto* s : idle) {
      s->close(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the stream was idle for more than " +
                                                               std::to_string(seconds) +
                                                               " s and was closed; open a new one to continue"));
      s->unref();
    }
    if (housekeeping_) housekeeping_();
    lock.lock();
  }
}

std::string StreamRegistry::clientOf(const grpc::ServerContextBase& ctx, bool tokens_enabled) {
  if (tokens_enabled) {
    const auto& md = ctx.client_metadata();
    const auto it = md.find("authorization");
    if (it != md.end())
      return "token:" + std::to_string(std::hash<std::string>{}(std::string(it->second.data(), it->second.size())));
  }
  // "ipv4:127.0.0.1:50312" -> "ipv4:127.0.0.1"; "ipv6:[::1]:50312" -> "ipv6:[::1]"
  std::string peer = ctx.peer();
  const auto colon = peer.rfind(':');
  if ((peer.rfind("ipv4:", 0) == 0 || peer.rfind("ipv6:", 0) == 0) && colon > 5) peer.resize(colon);
  return peer;
}

}  // namespace sglc::server
