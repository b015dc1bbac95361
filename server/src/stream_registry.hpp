// Open streams: how many each client may hold, which ones have idled too long, and closing them all.
//
// Streams (IngestStream, IngestChunked, WatchMap) are callback reactors that hold no thread while idle, but
// each still holds memory and a slot of the client's connection. A client (its bearer token when tokens are
// on, else its IP address) may hold at most `max_per_client` streams of each kind and the server at most
// `max_total` of each kind: the stream beyond is refused with RESOURCE_EXHAUSTED, nobody else is affected.
// An ingest stream that has waited for its client longer than `idle_timeout` is ended with UNAVAILABLE. A
// housekeeping thread checks once a second (and runs the given housekeeping hook, e.g. memory trimming).
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

namespace sglc::server {

struct StreamLimits {
  int max_per_client = 32;
  int max_total = 1024;
  std::chrono::milliseconds idle_timeout{std::chrono::seconds(120)};
};

// A stream the registry can end. Reference counted: gRPC's reference is dropped in OnDone, the registry pins
// a stream while it closes it, so a reactor is deleted by whoever lets go last.
class RegisteredStream {
 public:
  virtual ~RegisteredStream() = default;
  // Since when the stream waits for its client, or nullopt while it works (or never expires, like WatchMap).
  virtual std::optional<std::chrono::steady_clock::time_point> idleSince() = 0;
  // Ends the stream with `status` (no-op if it has ended). Must not be called with registry locks held.
  virtual void close(const grpc::Status& status) = 0;
  void ref() { refs_.fetch_add(1); }
  void unref() {
    if (refs_.fetch_sub(1) == 1) delete this;
  }

 private:
  std::atomic<int> refs_{1};
};

class StreamRegistry {
 public:
  enum class Kind { kIngest, kWatch };
  StreamRegistry(StreamLimits limits, std::function<void()> housekeeping);
  ~StreamRegistry();
  StreamRegistry(const StreamRegistry&) = delete;
  StreamRegistry& operator=(const StreamRegistry&) = delete;

  // Registers an open stream; throws RpcError(RESOURCE_EXHAUSTED) when the client or the server is at its
  // limit for that kind. Returns the id to leave() with.
  std::uint64_t admit(Kind kind, const std::string& client, RegisteredStream* stream);
  void leave(std::uint64_t id);
  // Ends every open stream with `status` (shutdown); streams admitted afterwards are refused.
  void closeAll(const grpc::Status& status);
  int open(Kind kind) const;

  // The client a limit applies to: "token:<hash>" when the call carries a bearer token, else the peer's address
  // without its port.
  static std::string clientOf(const grpc::ServerContextBase& ctx, bool tokens_enabled);

 private:
  struct Entry {
    Kind kind;
    std::string client;
    RegisteredStream* stream;
  };
  void housekeepingLoop();

  const StreamLimits limits_;
  std::function<void()> housekeeping_;
  mutable std::mutex mutex_;
  std::condition_variable stop_cv_;
  std::map<std::uint64_t, Entry> streams_;
  std::map<std::pair<Kind, std::string>, int> per_client_;
  std::map<Kind, int> per_kind_;
  std::uint64_t next_id_ = 1;
  bool closed_ = false, stop_ = false;
  std::thread thread_;
};

}  // namespace sglc::server
